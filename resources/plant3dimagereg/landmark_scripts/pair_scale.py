"""The thermal/infrared pixel scale measured from the landmark pairs alone (no rig): for two
infrared-thermal pairs of one plant at nearly the same depth (|dz| < DZ, default 30 mm) and at
least 20 infrared px apart, ||thermal difference|| / ||infrared difference|| (the points as read,
``feature_ir`` / ``feature_other`` of ``annotations.json``, before finalize.py's inward step).
finalize.py moves the thermal point by x 2.2 thermal px per infrared px; this is the scale the
readings themselves give (issue 23, session 11; README "Session 11").

  cd resources/plant3dimagereg/landmark_scripts && PYTHONPATH=../../.. python pair_scale.py [DZ_MM]
"""
from __future__ import annotations

import itertools
import json
import sys
from pathlib import Path

import numpy as np

from annotate_view import load
from plantreg_gui.core.rigfit.rigfit import landmark_depth

HERE = Path(__file__).resolve().parent


def main() -> None:
    dz_max = float(sys.argv[1]) / 1000 if len(sys.argv) > 1 else 0.03
    ann = json.loads((HERE / "annotations.json").read_text())
    allr = []
    for key in sorted(ann):
        plant, cam = key.split("/")
        if cam != "thermal":
            continue
        d = load(plant, "depth") / 1000.0
        pts = [(np.asarray(it["feature_ir"], float), np.asarray(it["feature_other"], float),
                landmark_depth(d, np.asarray(it["ir"], float))[0], it["note"]) for it in ann[key]]
        rs = []
        for (a, b, za, na), (c, e, zc, nc) in itertools.combinations(pts, 2):
            di = np.linalg.norm(a - c)
            if abs(za - zc) < dz_max and di >= 20:
                r = float(np.linalg.norm(b - e) / di)
                rs.append(r)
                print(f"{plant:15s} z {za:.3f}/{zc:.3f}  ir dist {di:6.1f}  ratio {r:5.2f}   {na[:34]} | {nc[:34]}")
        if rs:
            print(f"{plant}: {len(rs)} pairs of pairs, median ratio {np.median(rs):.2f} (range {min(rs):.2f}-{max(rs):.2f})")
            allr += rs
    print(f"all plants: {len(allr)}, median {np.median(allr):.2f}, quartiles {np.percentile(allr, 25):.2f}-{np.percentile(allr, 75):.2f}")


if __name__ == "__main__":
    main()
