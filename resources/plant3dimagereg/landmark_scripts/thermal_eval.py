"""Held-out figures for the thermal landmarks (issue 8, session land12).

``heldout RIG [LANDMARKS]``: residuals of a rig on landmarks, no fitting (default: ``rig.json`` is
given as RIG by the user, LANDMARKS = ``landmarks_heldout.json``, all 7 points kept out of rig.json's
fit: 5 located with its predictions (session land12), 2 read without them (session landmarks) —
``refit_eval.py check`` splits them by kind).

``compare [WAY ...]``: on all 31 landmarks (``landmarks.json`` + the 5 land12 pairs of
``landmarks_heldout.json``, see ``heldout_landmarks``; env LANDMARKS=FILE for one file), for each
way of fitting, the fitted residuals and two held-out measures per camera — leave-one-plant-out
(LOPO: the plant's landmarks of every camera left out of the fit) and, for the thermal camera,
leave-one-landmark-out (LOLO: one thermal landmark left out at a time, everything else in). Ways of fitting:

* ``joint FREE``: one ``plantreg fit-rig --free FREE`` over all landmarks (what
  ``fit_and_check.sh`` does with ``landmarks.json``);
* ``2stage FREE``: the infrared intrinsics (``FREE`` without its ``thermal:`` items) and the
  hyperspectral pose from the hyperspectral landmarks only, then the thermal pose (and the
  ``thermal:`` items of ``FREE``) from the thermal landmarks with the infrared held fixed
  (tested, not shipped: README, "Fit"). Nested: a LOPO fold repeats both stages without the plant.

  cd resources/plant3dimagereg/landmark_scripts && PYTHONPATH=../../.. python thermal_eval.py compare
  cd resources/plant3dimagereg/landmark_scripts && PYTHONPATH=../../.. python thermal_eval.py heldout ../rig.json
"""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path

import numpy as np

from plantreg_gui.core.data.landmarks import Landmark
from plantreg_gui.core.data.recording import Recording
from plantreg_gui.core.camera.rig import Rig
from plantreg_gui.core.rigfit.rigfit import RecordingLandmarks, evaluate_landmarks, fit_rig, parse_free

HERE = Path(__file__).resolve().parent
RES = HERE.parent


def load(path: Path, rig: Rig, kind: str | None = None) -> list[RecordingLandmarks]:
    """The landmarks of ``path``; ``kind``: only the points with that ``"held_out_kind"``."""
    doc = json.loads(path.read_text())
    out = []
    for key, r in sorted(doc["recordings"].items()):
        lms = [Landmark(np.array(p["depth_uv"], float), {c: np.array(uv, float) for c, uv in p["cameras"].items()},
                        p.get("note", "")) for p in r["points"] if kind is None or p.get("held_out_kind") == kind]
        if not lms:
            continue
        out.append(RecordingLandmarks(key, Recording.load(path.parent / key).depth_m(rig.depth_scale), lms))
    return out


def heldout_landmarks(rig: Rig) -> list[RecordingLandmarks]:
    """The pairs of ``landmarks_heldout.json`` these sessions' figures are of: by default the 5 of
    session land12 (``"held_out_kind": "found_with_rig"``); env HELD_OUT_KIND=independent for the 2
    read without a rig's prediction (session landmarks), HELD_OUT_KIND=all for all 7."""
    kind = os.environ.get("HELD_OUT_KIND", "found_with_rig")
    return load(RES / "landmarks_heldout.json", rig, None if kind == "all" else kind)


def all_landmarks(rig: Rig) -> list[RecordingLandmarks]:
    """``landmarks.json`` and the held-out pairs of ``heldout_landmarks`` together (31 points by
    default; LANDMARKS=FILE: that file alone), one entry per recording, the held-out points after
    the fitted ones."""
    if os.environ.get("LANDMARKS"):
        return load(Path(os.environ["LANDMARKS"]), rig)
    recs = {r.name: r for r in load(RES / "landmarks.json", rig)}
    for r in heldout_landmarks(rig):
        if r.name in recs:
            recs[r.name].points.extend(r.points)
        else:
            recs[r.name] = r
    return [recs[k] for k in sorted(recs)]


def only(recs: list[RecordingLandmarks], cam: str | None = None, drop_rec: str | None = None,
         drop: tuple[str, str, int] | None = None) -> list[RecordingLandmarks]:
    """The landmarks of camera ``cam`` (all if None), without recording ``drop_rec`` and without
    landmark ``drop`` = (recording, camera, index among that recording's points of that camera)."""
    out = []
    for r in recs:
        if r.name == drop_rec:
            continue
        pts, k = [], 0
        for lm in r.points:
            cams = {c: uv for c, uv in lm.cameras.items() if cam is None or c == cam}
            if drop is not None and drop[0] == r.name and drop[1] in lm.cameras:
                if k == drop[2]:
                    cams.pop(drop[1], None)
                k += 1
            if cams:
                pts.append(Landmark(lm.depth_uv, cams, lm.note))
        if pts:
            out.append(RecordingLandmarks(r.name, r.depth_m, pts))
    return out


def fit(kind: str, free: str, start: Rig, recs: list[RecordingLandmarks]) -> Rig:
    if kind == "joint":
        return fit_rig(start, recs, free=parse_free(free) if free else frozenset(), loo=False).rig
    items = [x for x in free.split(",") if x]
    f1 = parse_free(",".join(x for x in items if not x.startswith("thermal:"))) if items else frozenset()
    f2 = [x for x in items if x.startswith("thermal:")]
    hs = fit_rig(start, only(recs, "hyperspectral"), free=f1, loo=False).rig
    return fit_rig(hs, only(recs, "thermal"), free=parse_free(",".join(f2)) if f2 else frozenset(), loo=False).rig


def stats(v: list[float]) -> str:
    a = np.asarray(v)
    return f"median {np.median(a):5.2f} p90 {np.percentile(a, 90):5.2f} (n {a.size})" if a.size else "-"


def compare(configs: list[str]) -> None:
    start = Rig.load(RES / "rig_nominal.json")
    recs = all_landmarks(start)
    for cfg in configs:
        kind, _, free = cfg.partition(" ")
        rig = fit(kind, free, start, recs)
        rows, _ = evaluate_landmarks(rig, recs)
        print(f"== {kind} free={free or '(poses only)'}")
        for c in ("hyperspectral", "thermal"):
            v = [d["residual_px"] for d in rows if d["camera"] == c]
            print(f"   {c:13s} fitted (all, incl. rejected) {stats(v)}; without the worst: {stats(sorted(v)[:-1])}")
        lopo: dict[str, list[float]] = {}
        for r in recs:
            try:
                rr = fit(kind, free, start, only(recs, drop_rec=r.name))
            except Exception as e:  # too few landmarks left for a camera
                print(f"   LOPO {r.name}: unavailable ({e})")
                continue
            held, _ = evaluate_landmarks(rr, [r])
            per = {}
            for d in held:
                lopo.setdefault(d["camera"], []).append(d["residual_px"])
                per.setdefault(d["camera"], []).append(d["residual_px"])
            print(f"   LOPO {r.name}: " + ", ".join(f"{c} {np.median(v):.2f} (n {len(v)})" for c, v in sorted(per.items())))
        for c, v in sorted(lopo.items()):
            print(f"   LOPO {c:13s} {stats(v)}")
        lolo = []
        for r in recs:
            n = sum("thermal" in lm.cameras for lm in r.points)
            for k in range(n):
                rr = fit(kind, free, start, only(recs, drop=(r.name, "thermal", k)))
                held, _ = evaluate_landmarks(rr, only([r], "thermal"))
                d = [x for x in held if x["index"] == k][0]
                lolo.append(d["residual_px"])
                print(f"      LOLO thermal {r.name} #{k} {d['note'][:60]:60s} {d['residual_px']:6.2f} px")
        print(f"   LOLO thermal       {stats(lolo)}; without the worst: {stats(sorted(lolo)[:-1])}")


def heldout(rig_path: str, lm_path: str | None) -> None:
    rig = Rig.load(rig_path)
    recs = load(Path(lm_path) if lm_path else RES / "landmarks_heldout.json", rig)
    rows, rej = evaluate_landmarks(rig, recs)
    for d in rows:
        print(f"{d['residual_px']:7.2f} px  {d['camera']:13s} {d['recording']} #{d['index']} {d['note']}")
    for d in rej:
        print("no depth:", d)


if __name__ == "__main__":
    if sys.argv[1] == "heldout":
        heldout(sys.argv[2], sys.argv[3] if len(sys.argv) > 3 else None)
    else:
        compare(sys.argv[2:] or ["joint ir:k1", "2stage ir:k1", "joint ", "2stage "])
