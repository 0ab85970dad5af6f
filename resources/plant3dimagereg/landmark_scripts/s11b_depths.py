"""Depth check of the session-11b readings (eye_readings_s11b.json): for each pair, the mean of the
two infrared readings, finalize.py's inward step onto valid leaf depth (same rule: up to 10 px
towards the plant-mask centroid within 8 px until the pixel is on the plant, consistent with its
3x3 neighbourhood and with the leaf 4 px further in), and plantreg's own check
(`rigfit.check_landmark_depth`) at the point as read and after the step. Reads no rig.

  python s11b_depths.py            (from landmark_scripts/, PYTHONPATH = the project root)
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parents[2]))
from annotate_view import load  # noqa: E402
from finalize import inward_normal  # noqa: E402
from plantreg_gui.core.rigfit.rigfit import check_landmark_depth  # noqa: E402

GROUND_Z = 1.15  # the ROI's far limit in rig_nominal.json (the tray's floor lies beyond)


def step_onto_leaf(plant: str, pi: np.ndarray, d: np.ndarray) -> float | None:
    ni = inward_normal(plant, "ir", pi, 8.0)
    for s in np.arange(0.0, 10.01, 0.5):
        u, v = np.round(pi + ni * s).astype(int)
        blk = d[v - 1:v + 2, u - 1:u + 2].astype(float)
        ok = blk[blk > 0]
        u2, v2 = np.round(pi + ni * (s + 4)).astype(int)
        inner = d[v2 - 1:v2 + 2, u2 - 1:u2 + 2].astype(float)
        inner = inner[inner > 0]
        if (blk.shape == (3, 3) and 0 < blk[1, 1] < 1130 and ok.size >= 7
                and np.max(np.abs(ok - np.median(ok))) < 15 and abs(blk[1, 1] - np.median(ok)) < 8
                and inner.size and abs(blk[1, 1] - np.median(inner)) < 25):
            return float(s), ni
    return None, ni


def main() -> None:
    rd = json.loads((HERE / "eye_readings_s11b.json").read_text())
    for name, r in rd.items():
        plant = name.split("/")[0]
        d = load(plant, "depth")
        a1, a2 = np.asarray(r["r1"]["ir"], float), np.asarray(r["r2"]["ir"], float)
        b1, b2 = np.asarray(r["r1"]["other"], float), np.asarray(r["r2"]["other"], float)
        pi = (a1 + a2) / 2
        c0 = check_landmark_depth(d / 1000.0, pi, GROUND_Z)
        s, ni = step_onto_leaf(plant, pi, d)
        if s is None:
            print(f"{name:28s} agree ir {np.linalg.norm(a1 - a2):.2f} th {np.linalg.norm(b1 - b2):.2f} | as read {c0.status} "
                  f"{c0.read_m:.3f} | NO valid depth within 10 px")
            continue
        p2 = pi + ni * s
        c1 = check_landmark_depth(d / 1000.0, p2, GROUND_Z)
        print(f"{name:28s} agree ir {np.linalg.norm(a1 - a2):.2f} th {np.linalg.norm(b1 - b2):.2f} | as read "
              f"{c0.status} {c0.read_m:.3f} m | step {s:.1f} px -> {np.round(p2, 2).tolist()} {c1.status} {c1.z_m:.3f} m")


if __name__ == "__main__":
    main()
