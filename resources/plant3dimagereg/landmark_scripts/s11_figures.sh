#!/bin/sh
# Every figure of README "Session 11" (issue 23): the shipped rig and the refit (fit-rig --free ir:k1
# from rig_nominal.json on landmarks.json's 26 pairs + the session-11 pairs outside the held-out third)
# on the held-out pairs by kind, leave one plant out for both pools on the same pairs, each new pair
# left out alone, and the same with finalize.py's thermal step at the pairs' own scale (x1.98,
# pair_scale.py) instead of x2.2. Run from resources/plant3dimagereg/landmark_scripts with PYTHONPATH =
# the project root (PYTHON: the interpreter); OUT (default /tmp/plant3dimagereg_s11) receives the refits.
set -e
OUT=${OUT:-/tmp/plant3dimagereg_s11}
PY=${PYTHON:-python}
mkdir -p "$OUT"
echo "== the readings' own thermal/infrared scale (no rig)"; $PY pair_scale.py | tail -3
echo "== shipped rig.json on the held-out pairs, by kind"; $PY refit_eval.py check ../rig.json
echo "== refit: fitted pairs and held-out pairs"; $PY refit_eval.py heldout ir:k1 --out "$OUT/refit.json"
echo "== refit on the held-out pairs, by kind"; $PY refit_eval.py check "$OUT/refit.json"
echo "== each new fit pair left out alone"; $PY refit_eval.py newloo ir:k1
echo "== leave one plant out, refit's pool, every pair of the plant measured"; $PY refit_eval.py lopo ir:k1 --fit-only --measure-all
echo "== leave one plant out, shipped pool (no session-11 pair), every pair measured"; $PY refit_eval.py lopo ir:k1 --fit-only --measure-all --no-s11
echo "== leave one plant out, refit's pool + the 5 land12 pairs"; $PY refit_eval.py lopo ir:k1 --fit-only --fit-land12 --measure-all
echo "== leave one plant out, shipped pool + the 5 land12 pairs"; $PY refit_eval.py lopo ir:k1 --fit-only --fit-land12 --measure-all --no-s11
$PY finalize.py --thermal-scale 1.98 --out "$OUT/annotations_198.json" >/dev/null
echo "== step x1.98: refit"; ANNOTATIONS="$OUT/annotations_198.json" $PY refit_eval.py heldout ir:k1 --out "$OUT/refit_198.json"
echo "== step x1.98: refit on the held-out pairs, by kind"; ANNOTATIONS="$OUT/annotations_198.json" $PY refit_eval.py check "$OUT/refit_198.json"
echo "== step x1.98: shipped rig on the held-out pairs"; ANNOTATIONS="$OUT/annotations_198.json" $PY refit_eval.py check ../rig.json
echo "== step x1.98: leave one plant out, refit's pool + land12"; ANNOTATIONS="$OUT/annotations_198.json" $PY refit_eval.py lopo ir:k1 --fit-only --fit-land12 --measure-all
