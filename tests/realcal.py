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


def herrera_session(realcal: Path, dst: Path, poses: list[str] | None = None) -> Path:
    """Herrera et al.'s set: cameras ``kinect`` (Kinect RGB 1280 x 1024) and ``external``
    (2784 x 1856), 8 x 6 inner corners, 40 mm squares; pose ``NNNN`` holds the images of that
    number. ``poses`` (e.g. ["0000", "0003"]) restricts the session to some poses."""
    src = Path(realcal) / "herrera_kinect_rgb"
    dst.mkdir(parents=True, exist_ok=True)
    for f in sorted((src / "c1_kinect_rgb").glob("*-c1.jpg")):
        num = f.name.split("-")[0]
        if poses is not None and num not in poses:
            continue
        (dst / num).mkdir(exist_ok=True)
        _link(f, dst / num / "kinect.jpg")
        ext = src / "c2_external_rgb" / f"{num}-c2.jpg"
        if ext.exists():
            _link(ext, dst / num / "external.jpg")
    meta = {"board": {"type": "chessboard", "columns": 8, "rows": 6, "square_size": 0.040},
            "cameras": {"kinect": {"modality": "visible"}, "external": {"modality": "visible"}}}
    (dst / "session.json").write_text(json.dumps(meta, indent=2))
    return dst


def lepton_session(realcal: Path, dst: Path, stamps: list[str] | None = None) -> Path:
    """The Lepton 3.5 + ZED 2i set: cameras ``thermal`` (120 x 160 pseudo-colour PNG) and
    ``rgb`` (ZED left 1280 x 720), 4 x 6 inner corners, 55 mm squares; pose = time stamp."""
    src = Path(realcal) / "lepton35_zed2i"
    dst.mkdir(parents=True, exist_ok=True)
    for f in sorted((src / "thermal").glob("thermal_*.png")):
        stamp = f.stem[len("thermal_"):]
        if stamps is not None and stamp not in stamps:
            continue
        (dst / stamp).mkdir(exist_ok=True)
        _link(f, dst / stamp / "thermal.png")
        z = src / "zed" / f"zed_{stamp}.jpg"
        if z.exists():
            _link(z, dst / stamp / "rgb.jpg")
    meta = {"board": {"type": "chessboard", "columns": 4, "rows": 6, "square_size": 0.055},
            "cameras": {"thermal": {"modality": "thermal"}, "rgb": {"modality": "visible"}}}
    (dst / "session.json").write_text(json.dumps(meta, indent=2))
    return dst
