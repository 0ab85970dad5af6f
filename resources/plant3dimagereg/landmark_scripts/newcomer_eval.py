"""What a newcomer gets from plantreg alone (issue 23, "figures to reach"): the 26 fitted pairs of
``landmarks.json`` as they were READ (``feature_ir`` / ``feature_other`` in annotations.json: the
mean of two eye readings on silhouette corners, before finalize.py moved each onto valid depth by
hand), fitted as ``fit-rig --free ir:k1`` from ``rig_nominal.json`` with the product's depth check
snapping clicks that read the ground (the default) or leaving them out (``--no-snap-depth``);
against the shipped, hand-stepped pairs. Every rig is then measured on the 7 held-out pairs (as
shipped), by ``"held_out_kind"``.

  cd resources/plant3dimagereg/landmark_scripts && PYTHONPATH=../../.. python newcomer_eval.py
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

import refit_eval as rv
from plantreg_gui.core.camera.rig import Rig
from plantreg_gui.core.data.landmarks import Landmark
from plantreg_gui.core.errors import InputError
from plantreg_gui.core.rigfit.rigfit import check_landmark_depth, evaluate_landmarks, fit_rig

HERE = Path(__file__).resolve().parent


def main() -> None:
    ann = json.loads((HERE / "annotations.json").read_text())
    start = Rig.load(HERE.parent / "rig_nominal.json")
    kinds = rv.held_out_kinds()
    raw, shipped, held = [], [], []
    for key, items in ann.items():
        plant, cam = key.split("/")
        for it in items:
            lm = Landmark(np.array(it["ir"], float), {cam: np.array(it["other"], float)}, it["note"])
            if it.get("held_out"):
                held.append((plant, cam, lm))
                continue
            shipped.append((plant, cam, lm))
            raw.append((plant, cam, Landmark(np.array(it["feature_ir"], float),
                                             {cam: np.array(it["feature_other"], float)}, it["note"])))
    counts: dict[str, int] = {}
    for r in rv.recs(raw, start):
        for lm in r.points:
            st = check_landmark_depth(r.depth_m, lm.depth_uv, start.ground_z).status
            counts[st] = counts.get(st, 0) + 1
    print(f"{len(raw)} pairs fitted, {len(held)} held out; the raw clicks' depth checks: {counts}")
    for name, sel, snap in (("shipped (stepped by hand)", shipped, True), ("as read, snapped (default)", raw, True),
                            ("as read, --no-snap-depth", raw, False)):
        recs = rv.recs(sel, start)
        for r in recs:
            r.snap_depth = snap
        try:
            res = fit_rig(start, recs, free="ir:k1")
        except InputError as e:
            print(f"== {name}: refused: {e}")
            continue
        rep = res.report
        loo = rep["leave_one_out"].get("per_camera", {})
        cams = []
        for c, v in rep["per_camera"].items():
            kind, lo = ("LOPO", loo[c]) if c in loo else ("LOLO", rep.get("leave_one_landmark_out", {}).get(c, {}))
            cams.append(f"{c} fitted {v['median_px']:.2f} (n {v['n']}), {kind} {lo.get('median_px', float('nan')):.2f}")
        print(f"== {name}: used {rep['landmarks_used']}, snapped {len(rep['landmarks_snapped'])}, left out "
              f"{len(rep['landmarks_rejected'])}, outliers {sum(d['outlier'] for d in rep['residuals'])}; "
              + "; ".join(cams))
        rows, _ = evaluate_landmarks(res.rig, rv.recs(held, start))
        by: dict[str, list[float]] = {}
        for d in rows:
            by.setdefault(kinds[(d["recording"].split("/")[-1], d["camera"], d["note"])], []).append(d["residual_px"])
        print("   held out: " + "; ".join(f"{k} {', '.join(f'{x:.2f}' for x in sorted(v))} (median {np.median(v):.2f})"
                                         for k, v in sorted(by.items()))
              + f"; all {len(rows)}: median {np.median([d['residual_px'] for d in rows]):.2f} px")


if __name__ == "__main__":
    main()
