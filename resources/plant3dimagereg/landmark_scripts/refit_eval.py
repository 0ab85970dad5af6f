"""Held-out figures for refitting ``rig.json`` from all landmark pairs (issue 23, item 6).

Every fit is ``plantreg fit-rig --rig rig_nominal.json --free FREE`` (``rigfit.fit_rig``, the
CLI's fit) on a subset of the pairs in ``annotations.json``; the pairs left out are measured with
``evaluate_landmarks`` (the rig's prediction after back-projection at the landmark's depth minus
the reading). Two ways of leaving pairs out, both fixed before any fit:

* ``lopo``: leave one plant out (every camera's pairs of that plant), for each plant with pairs
  (``--fit-only``: over the pairs of the fit alone; the 26 of ``landmarks.json`` leave too few thermal
  pairs without the grapevine or the philodendron for a thermal pose: those folds are reported unfitted);
* ``half SEED``: a fixed random half of each plant's pairs per camera (``numpy`` generator seeded
  with SEED; odd counts put the extra pair in half A), two folds: fit A measure B, fit B measure A.

``heldout [FREE]``: fit to the pairs not marked ``"held_out"`` (``landmarks.json``'s, and since session 11
the new pairs outside its held-out third), measure the ``"held_out"`` pairs; ``--out RIG`` writes the fit.
Environment ANNOTATIONS=FILE: another annotations file (``finalize.py --thermal-scale X --out FILE``).
``--fit-land12`` (with ``heldout`` and ``lopo --fit-only``): the refit of session landmarks, measured
and not shipped: the 5 land12 pairs (``"held_out_kind": "found_with_rig"``) join the fit (31 pairs),
only the 2 ``independent`` ones are held out.
``lopo ... --measure-all`` (with ``--fit-only``): each fold measured on every pair of the plant left out
(held out ones too), so that two pools are compared on the same pairs; ``--no-s11``: the pool without
the session-11 pairs (the shipped rig's procedure).
``newloo [FREE]``: each session-11 pair of the fit left out alone (fitted to everything else of the fit).
``rig RIG``: the residuals of RIG on all pairs, per camera and plant (no fitting).
``check RIG``: the residuals of RIG on the held-out pairs, per pair and per ``"held_out_kind"``
(``independent``: read without a rig's prediction in view; ``found_with_rig``: located with
rig.json's predictions, so they flatter it).
FREE: as for ``fit-rig --free`` (default ``ir:k1``), or ``2stage:FREE`` (see ``fit``).

  cd resources/plant3dimagereg/landmark_scripts && PYTHONPATH=../../.. python refit_eval.py lopo [FREE] [--fit-only] [--fit-land12]
  cd resources/plant3dimagereg/landmark_scripts && PYTHONPATH=../../.. python refit_eval.py half 23 [FREE]
  cd resources/plant3dimagereg/landmark_scripts && PYTHONPATH=../../.. python refit_eval.py heldout [FREE] [--fit-land12] [--out RIG]
  cd resources/plant3dimagereg/landmark_scripts && PYTHONPATH=../../.. python refit_eval.py rig ../rig.json
  cd resources/plant3dimagereg/landmark_scripts && PYTHONPATH=../../.. python refit_eval.py check ../rig.json
"""

from __future__ import annotations

import json
import os
import re
import sys
from pathlib import Path

import numpy as np

from plantreg_gui.core.data.landmarks import Landmark
from plantreg_gui.core.data.recording import Recording
from plantreg_gui.core.camera.rig import Rig
from plantreg_gui.core.errors import InputError
from plantreg_gui.core.rigfit.rigfit import RecordingLandmarks, evaluate_landmarks, fit_rig, parse_free

HERE = Path(__file__).resolve().parent
RES = HERE.parent
CAMS = ("hyperspectral", "thermal")


def pairs() -> list[tuple[str, str, Landmark]]:
    """(plant, camera, landmark) for every pair of annotations.json, in file order. Environment
    THERMAL_STEP=none: the thermal point as read (``feature_other``), without finalize.py's inward
    move (the infrared point keeps its move onto valid depth)."""
    ann = json.loads(annotations_path().read_text())
    nostep = os.environ.get("THERMAL_STEP") == "none"
    return [(k.split("/")[0], k.split("/")[1],
             Landmark(np.array(it["ir"], float),
                      {k.split("/")[1]: np.array(it["feature_other" if nostep and k.endswith("/thermal") else "other"], float)},
                      it.get("note", "")))
            for k in sorted(ann) for it in ann[k]]


def annotations_path() -> Path:
    """``annotations.json``, or the file named by the environment variable ANNOTATIONS (a variant
    written by ``finalize.py --thermal-scale X --out FILE``)."""
    return Path(os.environ["ANNOTATIONS"]) if os.environ.get("ANNOTATIONS") else HERE / "annotations.json"


_DEPTH: dict[str, np.ndarray] = {}


def recs(sel: list[tuple[str, str, Landmark]], rig: Rig) -> list[RecordingLandmarks]:
    out: dict[str, list[Landmark]] = {}
    for plant, _, lm in sel:
        out.setdefault(plant, []).append(lm)
    for p in out:
        if p not in _DEPTH:
            _DEPTH[p] = Recording.load(RES / "recordings" / p).depth_m(rig.depth_scale)
    return [RecordingLandmarks(f"recordings/{p}", _DEPTH[p], lms) for p, lms in sorted(out.items())]


NOT_FITTED: dict[str, str] = {}
"""The cameras the last :func:`fit` kept at their start pose (``fit_rig`` fits the cameras with enough
pairs and names the rest): their residuals measure ``rig_nominal.json``, not a fit."""


def fit(sel, start: Rig, free: str) -> Rig:
    """``FREE`` as for fit-rig; ``2stage:FREE``: first the hyperspectral pairs alone fit the
    infrared items of FREE and the hyperspectral pose, then the thermal pairs alone fit the
    thermal pose (and FREE's ``thermal:`` items) with the infrared fixed."""
    NOT_FITTED.clear()
    if free.startswith("2stage:"):
        items = [x for x in free[7:].split(",") if x]
        f1 = parse_free(",".join(x for x in items if not x.startswith("thermal:")))
        f2 = parse_free(",".join(x for x in items if x.startswith("thermal:")))
        r1 = fit_rig(start, recs([t for t in sel if t[1] == "hyperspectral"], start), free=f1, loo=False)
        r2 = fit_rig(r1.rig, recs([t for t in sel if t[1] == "thermal"], start), free=f2, loo=False)
        NOT_FITTED.update(r1.report.get("not_fitted", {}), **r2.report.get("not_fitted", {}))
        return r2.rig
    f = parse_free(free) if free else frozenset()
    try:
        r = fit_rig(start, recs(sel, start), free=f, loo=False)
    except InputError as e:
        # a camera left with too few pairs after the outlier rejection: fit the others (as
        # ``fit-rig --fit``) and leave that one at its start pose, named like a thin camera
        m = re.match(r"camera '([^']+)'", str(e))
        if not m:
            raise
        others = sorted({t[1] for t in sel} - {m.group(1)})
        r = fit_rig(start, recs([t for t in sel if t[1] in others], start),
                    free=frozenset(x for x in f if not x.startswith(m.group(1) + ":")), cameras=others, loo=False)
        NOT_FITTED[m.group(1)] = str(e)[:120]
    NOT_FITTED.update(r.report.get("not_fitted", {}))
    return r.rig


def residuals(rig: Rig, sel) -> dict[str, list[tuple[str, float]]]:
    rows, rejected = evaluate_landmarks(rig, recs(sel, rig))
    if rejected:
        raise SystemExit(f"landmarks without depth: {rejected}")
    out: dict[str, list[tuple[str, float]]] = {}
    for d in rows:
        out.setdefault(d["camera"], []).append((d["recording"].split("/")[-1], d["residual_px"]))
    return out


def report(title: str, res: dict[str, list[tuple[str, float]]]) -> None:
    print(title)
    for c in CAMS:
        v = res.get(c, [])
        if not v:
            continue
        a = np.array([x for _, x in v])
        per = {}
        for p, x in v:
            per.setdefault(p, []).append(x)
        print(f"  {c:13s} median {np.median(a):5.2f}  p90 {np.percentile(a, 90):5.2f}  n {a.size:2d}   "
              + ", ".join(f"{p[2:]} {np.median(x):.2f} (n {len(x)})" for p, x in sorted(per.items())))


def held_out_keys(fit_land12: bool = False) -> set[tuple[str, str, str]]:
    """(plant, camera, note) of the pairs marked ``"held_out"`` in annotations.json (a note alone
    is not unique: the lily's top leaf tip is a hyperspectral and a thermal pair). ``fit_land12``:
    only the ``independent`` ones (the 5 land12 pairs join the fit, as in the refit of session
    landmarks that was measured and not shipped)."""
    return {k for k, kind in held_out_kinds().items() if not fit_land12 or kind == "independent"}


def held_out_kinds() -> dict[tuple[str, str, str], str]:
    """(plant, camera, note) -> ``"held_out_kind"`` of the held-out pairs of annotations.json."""
    ann = json.loads(annotations_path().read_text())
    return {(*k.split("/"), it["note"]): it.get("held_out_kind", "?") for k in ann for it in ann[k]
            if it.get("held_out")}


def s11_keys() -> set[tuple[str, str, str]]:
    """(plant, camera, note) of the session-11 pairs (``"session"`` starting with ``s11``)."""
    ann = json.loads(annotations_path().read_text())
    return {(*k.split("/"), it["note"]) for k in ann for it in ann[k] if str(it.get("session", "")).startswith("s11")}


def check(rig: Rig) -> None:
    kinds = held_out_kinds()
    sel = [t for t in pairs() if (t[0], t[1], t[2].note) in kinds]
    rows, rejected = evaluate_landmarks(rig, recs(sel, rig))
    if rejected:
        raise SystemExit(f"landmarks without depth: {rejected}")
    by: dict[str, list[float]] = {}
    for d in sorted(rows, key=lambda d: (kinds[(d["recording"].split("/")[-1], d["camera"], d["note"])], d["recording"])):
        kind = kinds[(d["recording"].split("/")[-1], d["camera"], d["note"])]
        by.setdefault(f"{d['camera']} {kind}", []).append(d["residual_px"])
        print(f"  {kind:15s} {d['recording'].split('/')[-1]:15s} {d['camera']:8s} {d['residual_px']:6.2f} px "
              f"(du {d['du']:+6.2f}, dv {d['dv']:+6.2f})  {d['note'][:60]}")
    for k, v in sorted(by.items()):
        print(f"{k}: median {np.median(v):.2f} px, min {min(v):.2f}, max {max(v):.2f}, n {len(v)}")


def halves(all_pairs, seed: int) -> tuple[list, list]:
    rng = np.random.default_rng(seed)
    a, b = [], []
    groups: dict[tuple[str, str], list] = {}
    for t in all_pairs:
        groups.setdefault(t[:2], []).append(t)
    for key in sorted(groups):
        g = groups[key]
        idx = rng.permutation(len(g))
        k = (len(g) + 1) // 2
        a += [g[i] for i in sorted(idx[:k])]
        b += [g[i] for i in sorted(idx[k:])]
    return a, b


def main() -> None:
    land12 = "--fit-land12" in sys.argv
    fit_only = "--fit-only" in sys.argv
    measure_all = "--measure-all" in sys.argv  # lopo --fit-only: measure every pair of the plant left out
    no_s11 = "--no-s11" in sys.argv  # the pool without the session-11 pairs (the shipped rig's procedure)
    save = None
    if "--out" in sys.argv:  # heldout: write the fitted rig (then ``check OUT`` splits its held-out pairs by kind)
        i = sys.argv.index("--out")
        save = Path(sys.argv[i + 1])
        del sys.argv[i:i + 2]
    sys.argv = [a for a in sys.argv if a not in ("--fit-land12", "--fit-only", "--measure-all", "--no-s11")]
    cmd = sys.argv[1]
    start = Rig.load(RES / "rig_nominal.json")
    P = pairs()
    if no_s11:
        P = [t for t in P if (t[0], t[1], t[2].note) not in s11_keys()]
    if cmd == "rig":
        report(f"{sys.argv[2]} on all {len(P)} pairs (fitted or not)", residuals(Rig.load(sys.argv[2]), P))
    elif cmd == "check":
        print(f"{sys.argv[2]} on the held-out pairs of annotations.json")
        check(Rig.load(sys.argv[2]))
    elif cmd == "heldout":
        free = sys.argv[2] if len(sys.argv) > 2 else "ir:k1"
        held = held_out_keys(land12)
        fit_on = [t for t in P if (t[0], t[1], t[2].note) not in held]
        out = [t for t in P if (t[0], t[1], t[2].note) in held]
        r = fit(fit_on, start, free)
        if save:
            r.save(save)
        src = "landmarks.json + the 5 land12 pairs" if land12 else "landmarks.json"
        report(f"--free {free} fitted to the {len(fit_on)} pairs ({src}; in-sample)", residuals(r, fit_on))
        report(f"  the same rig on the {len(out)} held-out pairs", residuals(r, out))
    elif cmd == "lopo":
        free = sys.argv[2] if len(sys.argv) > 2 else "ir:k1"
        if fit_only:  # the pairs of the fit only (as fit-rig's own leave-one-out)
            P = [t for t in P if (t[0], t[1], t[2].note) not in held_out_keys(land12)]
        everything = pairs()
        held: dict[str, list] = {}
        for plant in sorted({p for p, _, _ in P}):
            measured = [t for t in (everything if measure_all else P) if t[0] == plant]
            try:
                r = residuals(fit([t for t in P if t[0] != plant], start, free), measured)
            except InputError as e:  # e.g. too few thermal pairs left without this plant
                print(f"  {plant} left out: no fit ({e}); its pairs are not in the figures below")
                continue
            for c in NOT_FITTED:  # kept at rig_nominal.json's pose: not a held-out figure of a fit
                if r.pop(c, None):
                    print(f"  {plant} left out: {c} not fitted ({NOT_FITTED[c]}); its {c} pairs are not in the figures below")
            for c, v in r.items():
                held.setdefault(c, []).extend(v)
        report(f"leave-one-plant-out, --free {free}, {len(P)} pairs", held)
    elif cmd == "newloo":  # each session-11 pair of the fit left out alone, everything else of the fit in
        free = sys.argv[2] if len(sys.argv) > 2 else "ir:k1"
        ann = json.loads(annotations_path().read_text())
        new = {(*k.split("/"), it["note"]) for k in ann for it in ann[k]
               if str(it.get("session", "")).startswith("s11") and not it.get("held_out")}
        fit_on = [t for t in P if (t[0], t[1], t[2].note) not in held_out_keys()]
        held: dict[str, list] = {}
        for key in sorted(new):
            out = [t for t in fit_on if (t[0], t[1], t[2].note) == key]
            for c, v in residuals(fit([t for t in fit_on if (t[0], t[1], t[2].note) != key], start, free), out).items():
                print(f"  {key[0]} {key[1]} left out: {v[0][1]:.2f} px  ({key[2][:60]})")
                held.setdefault(c, []).extend(v)
        report(f"each session-11 fit pair left out alone, --free {free}", held)
    elif cmd == "half":
        seed, free = int(sys.argv[2]), (sys.argv[3] if len(sys.argv) > 3 else "ir:k1")
        a, b = halves(P, seed)
        held: dict[str, list] = {}
        for fit_on, test_on in ((a, b), (b, a)):
            for c, v in residuals(fit(fit_on, start, free), test_on).items():
                if c in NOT_FITTED:
                    print(f"  a fold: {c} not fitted ({NOT_FITTED[c]}); its {c} pairs are not in the figures below")
                    continue
                held.setdefault(c, []).extend(v)
        report(f"fixed random half per plant and camera (seed {seed}), two folds, --free {free}: "
               f"halves of {len(a)} / {len(b)} pairs", held)
    else:
        raise SystemExit(__doc__)


if __name__ == "__main__":
    main()
