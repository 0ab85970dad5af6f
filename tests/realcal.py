"""Sessions built (as symlinks, in a temporary folder) from the real sets in ``shared/data/realcal``,
which are laid out as the publishers left them, not as plantreg sessions. Never writes into
``shared/``."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np


def _link(src: Path, dst: Path) -> None:
    dst.parent.mkdir(parents=True, exist_ok=True)
    os.symlink(src.resolve(), dst)


def herrera_session(shared: Path, dst: Path, views: list[str] | None = None) -> Path:
    """Herrera et al.'s Kinect RGB ('kinect', 1280 x 1024) + external RGB ('external',
    2784 x 1856), 8 x 6 board of 40 mm squares; one pose folder per view number (``views``:
    e.g. ["0000", "0003"]; default all 54 Kinect views, 38 of them with the external camera)."""
    src = shared / "realcal" / "herrera_kinect_rgb"
    dst.mkdir(parents=True)
    for f in sorted((src / "c1_kinect_rgb").glob("*-c1.jpg")):
        n = f.name.split("-")[0]
        if views is not None and n not in views:
            continue
        _link(f, dst / f"view_{n}" / "kinect.jpg")
        ext = src / "c2_external_rgb" / f"{n}-c2.jpg"
        if ext.is_file():
            _link(ext, dst / f"view_{n}" / "external.jpg")
    (dst / "session.json").write_text(json.dumps({
        "board": {"type": "chessboard", "columns": 8, "rows": 6, "square_size": 0.04},
        "cameras": {"kinect": {"modality": "visible"}, "external": {"modality": "visible"}}}))
    return dst


def herrera_reference(shared: Path) -> dict:
    """The published calibration: K of both cameras, and the external camera's pose in the
    Kinect's frame as (R_ext_kinect (3, 3), t_ext_kinect (3,) metres) (from Herrera's
    X_kinect = rR X_ext + rt)."""
    d = json.loads((shared / "realcal" / "herrera_kinect_rgb" / "reference" / "final_calib_full_set.json").read_text())
    c2 = d["cam2_external_rgb"]
    rR, rt = np.array(c2["rR_herrera"]), np.array(c2["rt_herrera_m"])
    return {"K_kinect": np.array(d["cam1_kinect_rgb"]["K"]), "K_external": np.array(c2["K"]),
            "R_ext_kinect": rR.T, "t_ext_kinect": -rR.T @ rt}


#: Herrera's toolbox's own calibration of the two RGB cameras alone, before its depth camera's
#: disparity planes are added (``calib0`` in the same full_set.mat as the published reference,
#: PyojinKim/Kinect_calibration_toolbox dataset_original/full_set.mat @a7c32e6; made by
#: toolbox/do_initial_rgb_calib.m: each camera from its corners, then one joint fit of both with
#: k1 k2 p1 p2 k3). The shared set has no depth images, so this is what its RGB images determine
#: by the toolbox's own method. K (3, 3) per camera, the external camera's pose as in
#: :func:`herrera_reference`.
_HERRERA_RGB_ONLY = {
    "K_kinect": [[1062.8678746222645, 0.0, 624.3686768884835], [0.0, 1056.497792923035, 511.7922722147588],
                 [0.0, 0.0, 1.0]],
    "K_external": [[4085.4078900371337, 0.0, 1426.0288552709465], [0.0, 4061.0025989591145, 869.7790013995603],
                   [0.0, 0.0, 1.0]],
    "rR": [[0.999344166831335, 4.951068095388527e-05, 0.03621096199878566],
           [-0.00025367148964122033, 0.9999840994172252, 0.005633521411721187],
           [-0.036210107303905774, -0.00563901245019457, 0.999328289236138]],
    "rt": [-0.010973155124676094, -0.06880421193225446, -0.01801468660872466],
}


def herrera_rgb_only_reference() -> dict:
    """Herrera's toolbox's joint calibration of the Kinect RGB and external cameras from their
    images alone (:data:`_HERRERA_RGB_ONLY`), in the form of :func:`herrera_reference`. The
    published reference adds the Kinect's depth images (not in the shared set), which move the
    Kinect's fx from 1062.87 to 1059.73 px and the external camera's from 4085.4 to 4073.1 px."""
    d = _HERRERA_RGB_ONLY
    rR, rt = np.array(d["rR"]), np.array(d["rt"])
    return {"K_kinect": np.array(d["K_kinect"]), "K_external": np.array(d["K_external"]),
            "R_ext_kinect": rR.T, "t_ext_kinect": -rR.T @ rt}


def lepton_session(shared: Path, dst: Path, stamps: list[str] | None = None) -> Path:
    """FLIR Lepton 3.5 ('thermal', 120 x 160 palette PNG) + ZED 2i left ('rgb', 1280 x 720):
    one pose folder per time stamp present in both; 4 x 6 board of 55 mm squares."""
    src = shared / "realcal" / "lepton35_zed2i"
    dst.mkdir(parents=True)
    for f in sorted((src / "thermal").glob("thermal_*.png")):
        stamp = f.stem[len("thermal_"):]
        z = src / "zed" / f"zed_{stamp}.jpg"
        if not z.is_file() or (stamps is not None and stamp not in stamps):
            continue
        _link(f, dst / f"t_{stamp}" / "thermal.png")
        _link(z, dst / f"t_{stamp}" / "rgb.jpg")
    (dst / "session.json").write_text(json.dumps({
        "board": {"type": "chessboard", "columns": 4, "rows": 6, "square_size": 0.055},
        "cameras": {"rgb": {"modality": "visible"}, "thermal": {"modality": "thermal"}}}))
    return dst


def writable_copy(src: Path, dst: Path) -> Path:
    """A copy of a shared session the user owns and may write into (the shared folders carry no
    write bits, and the wizard and the detection cache write only where the folder has them)."""
    import shutil

    shutil.copytree(src, dst)
    for d, _dirs, files in os.walk(dst):
        os.chmod(d, 0o755)
        for f in files:
            p = Path(d) / f
            if not p.is_symlink():
                os.chmod(p, 0o644)
    return dst
