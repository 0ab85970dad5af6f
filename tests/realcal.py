"""Calibration sessions laid out over the real sets in ``../shared/data/realcal`` (which stay
read-only): one folder per pose with symlinks named after the cameras, and a ``session.json``
from the sets' READMEs. Used by tests and ``benchmarks/bench_calibrate.py``."""

from __future__ import annotations

import json
import os
from pathlib import Path


def _link(src: Path, dst: Path) -> None:
    try:
        os.symlink(src, dst)
    except OSError:  # no symlinks (some file systems): a copy
        import shutil

        shutil.copy(src, dst)


def _layout(dst: Path, poses: dict[str, dict[str, Path]], meta: dict) -> Path:
    """``dst/POSE/CAMERA.ext`` -> the files of ``poses`` {pose: {camera: file}}, and session.json."""
    dst.mkdir(parents=True, exist_ok=True)
    for pose, files in poses.items():
        (dst / pose).mkdir(exist_ok=True)
        for cam, f in files.items():
            if f.exists():
                _link(f, dst / pose / f"{cam}{f.suffix}")
    (dst / "session.json").write_text(json.dumps(meta, indent=2))
    return dst


def herrera_session(realcal: Path, dst: Path, poses: list[str] | None = None) -> Path:
    """Herrera et al.'s set: cameras ``kinect`` (Kinect RGB 1280 x 1024) and ``external``
    (2784 x 1856), 8 x 6 inner corners, 40 mm squares; pose ``NNNN`` holds the images of that
    number. ``poses`` (e.g. ["0000", "0003"]) restricts the session to some poses."""
    src = Path(realcal) / "herrera_kinect_rgb"
    nums = [f.name.split("-")[0] for f in sorted((src / "c1_kinect_rgb").glob("*-c1.jpg"))]
    files = {n: {"kinect": src / "c1_kinect_rgb" / f"{n}-c1.jpg", "external": src / "c2_external_rgb" / f"{n}-c2.jpg"}
             for n in nums if poses is None or n in poses}
    meta = {"board": {"type": "chessboard", "columns": 8, "rows": 6, "square_size": 0.040},
            "cameras": {"kinect": {"modality": "visible"}, "external": {"modality": "visible"}}}
    return _layout(dst, files, meta)


def lepton_session(realcal: Path, dst: Path, stamps: list[str] | None = None) -> Path:
    """The Lepton 3.5 + ZED 2i set: cameras ``thermal`` (120 x 160 pseudo-colour PNG) and
    ``rgb`` (ZED left 1280 x 720), 4 x 6 inner corners, 55 mm squares; pose = time stamp."""
    src = Path(realcal) / "lepton35_zed2i"
    found = [f.stem[len("thermal_"):] for f in sorted((src / "thermal").glob("thermal_*.png"))]
    files = {t: {"thermal": src / "thermal" / f"thermal_{t}.png", "rgb": src / "zed" / f"zed_{t}.jpg"}
             for t in found if stamps is None or t in stamps}
    meta = {"board": {"type": "chessboard", "columns": 4, "rows": 6, "square_size": 0.055},
            "cameras": {"thermal": {"modality": "thermal"}, "rgb": {"modality": "visible"}}}
    return _layout(dst, files, meta)
