#!/bin/sh
# Fit the rig from the landmarks and register every plant with it (run from the project root).
#   sh resources/plant3dimagereg/landmark_scripts/fit_and_check.sh [FREE] [OUTDIR]
# FREE: --free items for plantreg fit-rig (default: the depth camera's k1, as for the shipped rig.json).
set -e
FREE=${1:-ir:k1}
OUT=${2:-/tmp/plant3dimagereg}
R=resources/plant3dimagereg
mkdir -p "$OUT"
plantreg fit-rig --rig $R/rig_nominal.json --landmarks $R/landmarks.json --out $R/rig.json \
    --free "$FREE" --worst 30 --overwrite | tee "$OUT/fit.txt"
for p in 01grapevine 02leopard_lily 03areca_palm 04philodendron 05boston_fern 06weeping_fig; do
    plantreg register --rig $R/rig.json --recording $R/recordings/$p --target ir --out "$OUT/$p" --overwrite --quiet
    (cd $R/landmark_scripts && python check_registration.py "$OUT/$p" $p "$OUT/check_$p.png")
done
