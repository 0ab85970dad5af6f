"""Speed of display rendering (interactive use) and of writing an output folder.

    .venv/bin/python benchmarks/bench_display_export.py

Prints milliseconds per call for the display paths at 640x576 and 3840x2160, and the
seconds per part of an export of a paper-sized result (infrared target 640x576; RGB,
thermal and a 204-band hyperspectral source), with the output sizes. Random data, fixed seed.
"""

from __future__ import annotations

import json
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np

from plantreg_gui.core.display import display
from plantreg_gui.core.camera.camera import Camera
from plantreg_gui.core.export.export import write_outputs
from plantreg_gui.core.registration.register import RegistrationParams, RegistrationResult
from plantreg_gui.core.camera.rig import Rig


def _time(fn, repeat=3) -> float:
    fn()  # warm-up (colour-map tables, BLAS threads)
    best = np.inf
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t)
    return best * 1e3


def bench_display() -> None:
    rng = np.random.default_rng(0)
    print("display rendering, best of 3 (ms)")
    for H, W in ((576, 640), (2160, 3840)):
        th = rng.normal(25, 2, (H, W)).astype(np.float32)
        th[: H // 10] = np.nan
        rgb8 = rng.integers(0, 256, (H, W, 3), dtype=np.uint8)
        rgbf = rgb8.astype(np.float32)
        codes = rng.integers(0, 7, (H, W)).astype(np.uint8)
        rows = {
            "thermal colour map": lambda: display.to_rgb8(th, "thermal"),
            "float RGB stretch": lambda: display.to_rgb8(rgbf, "rgb"),
            "case overlay": lambda: display.overlay(rgb8, codes, display.CASE_COLOURS, 0.5),
            "mosaic 4 images, tile 64": lambda: display.mosaic([rgb8] * 4, 64),
            "blend": lambda: display.blend(rgb8, rgb8[::-1], 0.3),
        }
        for name, fn in rows.items():
            print(f"  {W}x{H}  {name:28s} {_time(fn):8.1f}")
    for H, W, B in ((512, 512, 204), (576, 640, 204)):
        cube = rng.uniform(0, 1, (H, W, B)).astype(np.float32)
        print(f"  {W}x{H}x{B} PCA false colour      {_time(lambda: display.to_rgb8(cube, 'hyperspectral')):8.1f}")


def bench_export() -> None:
    rng = np.random.default_rng(1)
    H, W = 576, 640
    cams = [Camera("ir", "infrared", W, H, np.eye(3)), Camera("rgb", "rgb", 3840, 2160, np.eye(3)),
            Camera("thermal", "thermal", 640, 480, np.eye(3)), Camera("hs", "hyperspectral", 512, 512, np.eye(3))]
    rig = Rig(cams, "ir")
    pts = rng.uniform(-0.3, 0.3, (H, W, 3)).astype(np.float32)
    pts[:, : W // 3] = np.nan  # a third background
    reg = {"ir": rng.uniform(0, 3000, (H, W)).astype(np.float32),
           "rgb": rng.uniform(0, 255, (H, W, 3)).astype(np.float32),
           "thermal": rng.normal(25, 2, (H, W)).astype(np.float32),
           "hs": rng.uniform(0, 1, (H, W, 204)).astype(np.float32)}
    cases = {c: rng.integers(0, 7, (H, W)).astype(np.uint8) for c in ("rgb", "thermal", "hs")}
    res = RegistrationResult("ir", pts, np.full((H, W), 4, np.uint8), reg, {}, cases, RegistrationParams())
    tmp = Path(tempfile.mkdtemp())
    try:
        t = time.perf_counter()
        out = write_outputs(res, rig, None, tmp / "out")
        total = time.perf_counter() - t
        s = json.loads((out / "summary.json").read_text())
        print(f"export of a {W}x{H} target with RGB, thermal, 204-band cube: {total:.2f} s")
        for k, v in s["export_timings"].items():
            print(f"  {k:12s} {v:6.2f} s")
        for p in sorted(out.rglob("*")):
            if p.is_file():
                print(f"  {str(p.relative_to(out)):26s} {p.stat().st_size / 1e6:8.1f} MB")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    bench_display()
    bench_export()
