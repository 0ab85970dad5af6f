"""`plantreg calibrate` against OpenCV's plain pipeline on Herrera et al.'s Kinect RGB + external
RGB set (issue 19: plantreg within 5x of OpenCV), both measured in this one run.

    PYTHONPATH=. .venv/bin/python benchmarks/bench_calibrate.py [--poses N] [--data ../shared/data]

* OpenCV baseline, in this process: per image ``cv2.imread`` (grey) + ``findChessboardCorners``
  (adaptive threshold + normalise) + ``cornerSubPix`` 11 x 11, then ``calibrateCamera`` per
  camera and ``stereoCalibrate`` (intrinsics fixed) on the poses both cameras found.
* plantreg end to end as a user runs it: ``python -m plantreg_gui calibrate SESSION --out ...
  --report ...`` as a subprocess (start-up included), first without a detection cache, then the
  re-run that finds ``detections.json``. plantreg's split: detection = first run - re-run (the
  re-run detects nothing), solve = re-run - start-up (``python -m plantreg_gui --version``).

The session is laid out over the read-only set with symlinks in a temporary folder. The
machine's load (``uptime``) is printed beside each figure: figures on a loaded machine are
inflated, the ratios less so.

plantreg runs as installed: its modules compiled to bytecode once beforehand, as ``pip install``
does (into a cache folder in the temporary folder, ``PYTHONPYCACHEPREFIX``). An environment that
sets ``PYTHONDONTWRITEBYTECODE`` (as this development machine's does) would otherwise make every
process, and every detection worker, compile ~50 modules from source at each start;
``--no-bytecode`` measures that case.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from realcal import herrera_session  # noqa: E402  (one layout for tests and benchmark)


def load() -> str:
    return os.getloadavg().__repr__() if hasattr(os, "getloadavg") else "?"


def opencv_baseline(session: Path, cameras: list[str], pattern: tuple[int, int], square: float) -> dict:
    """OpenCV's plain pipeline; returns seconds of detection and of the solve, fx per camera and the
    corners ("corners": camera -> pose -> (N, 1, 2) in OpenCV's order)."""
    obj = np.zeros((pattern[0] * pattern[1], 3), np.float32)
    obj[:, :2] = np.mgrid[0:pattern[0], 0:pattern[1]].T.reshape(-1, 2) * square
    crit = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 30, 0.01)
    t0 = time.perf_counter()
    found: dict[str, dict[str, np.ndarray]] = {c: {} for c in cameras}
    sizes = {}
    for pose in sorted(p for p in session.iterdir() if p.is_dir()):
        for cam in cameras:
            f = pose / f"{cam}.jpg"
            if not f.exists():
                continue
            g = cv2.imread(str(f), cv2.IMREAD_GRAYSCALE)
            sizes[cam] = g.shape[::-1]
            ok, c = cv2.findChessboardCorners(g, pattern, flags=cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE)
            if ok:
                found[cam][pose.name] = cv2.cornerSubPix(g, c, (11, 11), (-1, -1), crit)
    t1 = time.perf_counter()
    K, D = {}, {}
    for cam in cameras:
        views = sorted(found[cam])
        _, K[cam], D[cam], _, _ = cv2.calibrateCamera([obj] * len(views), [found[cam][v] for v in views],
                                                      sizes[cam], None, None)
    shared = sorted(set(found[cameras[0]]) & set(found[cameras[1]]))
    rms, *_ = cv2.stereoCalibrate([obj] * len(shared), [found[cameras[0]][v] for v in shared],
                                  [found[cameras[1]][v] for v in shared], K[cameras[0]], D[cameras[0]],
                                  K[cameras[1]], D[cameras[1]], sizes[cameras[0]], flags=cv2.CALIB_FIX_INTRINSIC)
    t2 = time.perf_counter()
    return {"detect_s": t1 - t0, "solve_s": t2 - t1, "total_s": t2 - t0,
            "found": {c: len(found[c]) for c in cameras}, "fx": {c: float(K[c][0, 0]) for c in cameras},
            "stereo_rms": float(rms), "corners": found}


#: the environment plantreg's processes run in (:func:`installed_env`)
ENV = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))


def installed_env(cache: Path) -> None:
    """Run plantreg as installed: bytecode compiled once into ``cache`` (what pip does)."""
    ENV.pop("PYTHONDONTWRITEBYTECODE", None)
    ENV["PYTHONPYCACHEPREFIX"] = str(cache)
    subprocess.run([sys.executable, "-m", "compileall", "-q", str(ROOT / "plantreg_gui")], env=ENV, check=True,
                   capture_output=True)


def plantreg_run(session: Path, out: Path, overwrite: bool) -> tuple[float, str]:
    cmd = [sys.executable, "-m", "plantreg_gui", "calibrate", str(session), "--out", str(out / "rig.json"),
           "--report", str(out / "report.json"), "--quiet"] + (["--overwrite"] if overwrite else [])
    env = ENV
    t0 = time.perf_counter()
    r = subprocess.run(cmd, capture_output=True, text=True, env=env)
    dt = time.perf_counter() - t0
    if r.returncode != 0:
        raise SystemExit(f"plantreg calibrate failed ({r.returncode}): {r.stderr.strip()}")
    return dt, r.stdout


def startup() -> float:
    env = ENV
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "plantreg_gui", "--version"], capture_output=True, env=env, check=True)
    return time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=ROOT.parent / "shared" / "data")
    ap.add_argument("--poses", type=int, default=0, help="only the first N poses (0 = all)")
    ap.add_argument("--no-bytecode", action="store_true",
                    help="keep the environment's PYTHONDONTWRITEBYTECODE: every process compiles plantreg from source")
    a = ap.parse_args()
    realcal = a.data / "realcal"
    with tempfile.TemporaryDirectory(prefix="bench_calibrate_") as tmp:
        tmp = Path(tmp)
        poses = None
        if a.poses:
            poses = sorted(f.name.split("-")[0] for f in (realcal / "herrera_kinect_rgb" / "c1_kinect_rgb").glob("*-c1.jpg"))[:a.poses]
        session = herrera_session(a.data, tmp / "herrera", poses)
        n_img = sum(1 for p in session.iterdir() if p.is_dir() for _ in p.iterdir())
        out = tmp / "out"
        out.mkdir()
        if not a.no_bytecode:
            installed_env(tmp / "pycache")
        print("plantreg's modules: " + ("compiled from source in every process" if a.no_bytecode
                                        else "bytecode compiled once, as installed"))
        print(f"Herrera set: {n_img} images, cores {os.cpu_count()}")
        print(f"load before: {load()}")
        cv_ = opencv_baseline(session, ["kinect", "external"], (8, 6), 0.040)
        print(f"OpenCV plain pipeline: {cv_['total_s']:.2f} s (detection {cv_['detect_s']:.2f} s, solve "
              f"{cv_['solve_s']:.2f} s); boards found {cv_['found']}; fx {cv_['fx']}; stereo RMS "
              f"{cv_['stereo_rms']:.3f} px   [load {load()}]")
        t_first, stdout = plantreg_run(session, out, overwrite=False)
        print(f"plantreg calibrate, first run (detects): {t_first:.2f} s = {t_first / cv_['total_s']:.1f}x OpenCV   "
              f"[load {load()}]")
        t_again, _ = plantreg_run(session, out, overwrite=True)
        print(f"plantreg calibrate, re-run (detections cached): {t_again:.2f} s = {t_again / cv_['total_s']:.1f}x "
              f"OpenCV   [load {load()}]")
        t_start = startup()
        print(f"plantreg split: start-up {t_start:.2f} s, detection {t_first - t_again:.2f} s "
              f"({(t_first - t_again) / cv_['detect_s']:.1f}x OpenCV's), solve + tables {t_again - t_start:.2f} s "
              f"({(t_again - t_start) / max(cv_['solve_s'], 1e-9):.1f}x OpenCV's)   [load {load()}]")
        print("plantreg summary: " + stdout.splitlines()[0])


if __name__ == "__main__":
    main()
