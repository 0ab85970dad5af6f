#!/bin/sh
# Fit the rig from the landmarks and register every plant with it (run from the project root,
# venv active, PYTHONPATH = project root).
#   sh resources/plant3dimagereg/tools/fit_and_check.sh [FREE] [OUTDIR]
# FREE: --free items (default ir:k1,thermal:k1, the shipped rig). Two stages (README, "Fit"):
#   1. the hyperspectral landmarks fit the infrared lens (FREE's non-thermal items) and the
#      hyperspectral pose;
#   2. the thermal landmarks fit the thermal camera (pose and FREE's thermal: items) with the
#      infrared held as stage 1 left it.
# JOINT=1: one joint fit of all landmarks with FREE instead (the rig shipped before session land12).
set -e
FREE=${1:-ir:k1,thermal:k1}
OUT=${2:-/tmp/plant3dimagereg}
R=resources/plant3dimagereg
mkdir -p "$OUT"
if [ -n "$JOINT" ]; then
    plantreg fit-rig --rig $R/rig_nominal.json --landmarks $R/landmarks.json --out $R/rig.json \
        --free "$FREE" --worst 30 --overwrite | tee "$OUT/fit.txt"
else
    F1=$(echo "$FREE" | tr , '\n' | grep -v '^thermal:' | paste -sd, -)
    F2=$(echo "$FREE" | tr , '\n' | grep '^thermal:' | paste -sd, -)
    python $R/tools/landmarks_for_camera.py hyperspectral "$OUT/landmarks_hyperspectral.json"
    python $R/tools/landmarks_for_camera.py thermal "$OUT/landmarks_thermal.json"
    plantreg fit-rig --rig $R/rig_nominal.json --landmarks "$OUT/landmarks_hyperspectral.json" \
        --out "$OUT/rig_stage1.json" ${F1:+--free "$F1"} --worst 30 --overwrite | tee "$OUT/fit.txt"
    plantreg fit-rig --rig "$OUT/rig_stage1.json" --landmarks "$OUT/landmarks_thermal.json" \
        --out $R/rig.json ${F2:+--free "$F2"} --worst 30 --overwrite | tee -a "$OUT/fit.txt"
    python $R/tools/rig_provenance.py "$OUT/rig_stage1.json" $R/rig.json
fi
for p in 01grapevine 02leopard_lily 03areca_palm 04philodendron 05boston_fern 06weeping_fig; do
    plantreg register --rig $R/rig.json --recording $R/recordings/$p --target ir --out "$OUT/$p" --overwrite --quiet
    (cd $R/tools && python check_registration.py "$OUT/$p" $p "$OUT/check_$p.png")
done
