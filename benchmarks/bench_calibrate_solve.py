"""The solver's share of ``plantreg calibrate`` against OpenCV's plain pipeline, on the same images.

    PYTHONPATH=. .venv/bin/python benchmarks/bench_calibrate_solve.py [--set herrera|stereo] [--repeat 2]

Detects the board once (plantreg's detector; not timed here: benchmarks/bench_calibrate.py times
the whole command), then times in one run, alternating: OpenCV's plain pipeline
(findChessboardCorners + cornerSubPix 11 x 11 on every image, calibrateCamera per camera,
stereoCalibrate) and plantreg's solve (lens model cross-validation, joint fits, covariance,
uncertainty) plus its error tables on the same detections. Prints both and their ratio with the
machine's load (a ratio, never a wall-clock figure alone).
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--set", choices=("herrera", "stereo"), default="herrera")
    ap.add_argument("--repeat", type=int, default=2)
    a = ap.parse_args(argv)
    from plantreg_gui.core.calibration import Session, calibrate, detect_session, error_tables

    shared = Path(os.environ.get("PLANTREG_SHARED_DATA", ROOT.parent / "shared" / "data"))
    if a.set == "herrera":
        from realcal import herrera_session

        folder = herrera_session(shared, Path(tempfile.mkdtemp(prefix="bench-herrera-")) / "session")
    else:
        folder = shared / "opencv-stereo"
    s = Session.load(folder)
    dets = {d.key: d for d in detect_session(s)}
    cams = list(s.cameras)
    obj = s.board.object_points().astype(np.float32)

    def plain() -> None:
        found = {}
        for k, d in sorted(dets.items()):
            if d.path is None:  # no image of this camera in this pose
                continue
            g = cv2.imread(str(d.path), cv2.IMREAD_GRAYSCALE)
            ok, c = cv2.findChessboardCorners(g, s.board.pattern_size,
                                              flags=cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE)
            if ok:
                found[k] = cv2.cornerSubPix(g, c, (11, 11), (-1, -1),
                                            (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 30, 0.01))
        res = {}
        for c in cams:
            ks = sorted(k for k in found if k[1] == c)
            res[c] = cv2.calibrateCamera([obj] * len(ks), [found[k] for k in ks], dets[ks[0]].image_size, None, None)
        a_, b_ = cams[:2]
        sh = sorted(p for (p, c) in found if c == a_ and (p, b_) in found)
        cv2.stereoCalibrate([obj] * len(sh), [found[(p, a_)] for p in sh], [found[(p, b_)] for p in sh],
                            res[a_][1], res[a_][2], res[b_][1], res[b_][2], dets[(sh[0], a_)].image_size,
                            flags=cv2.CALIB_FIX_INTRINSIC)

    for _ in range(a.repeat):
        t = time.perf_counter()
        plain()
        tp = time.perf_counter() - t
        t = time.perf_counter()
        cal = calibrate(s, dets)
        error_tables(s, cal, dets)
        ts = time.perf_counter() - t
        print(f"{a.set}: OpenCV plain pipeline {tp:.2f} s; plantreg solve + tables {ts:.2f} s = {ts / tp:.2f} x "
              f"(load {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
