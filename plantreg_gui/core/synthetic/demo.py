"""The demo rig (placed like the paper's rig) and ``write_demo``: rig, recording, ground truth and
calibration session of the synthetic plant, written to one folder.

Rig frame = the infrared/depth camera's frame: x right, y down, z forward; the camera looks
straight down onto the ground plane at z = 1.20 m. The ROI's max z is 1.17 m, so the ROI crop
removes the ground and keeps pot, soil, stems and leaves.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from ..camera.camera import Camera
from ..errors import InputError
from ..io.imageio import atomic_output_dir, atomic_write_text, write_png, write_tiff
from ..progress import Reporter, ensure_reporter
from ..camera.rig import Rig
from .render import ground_truth, render_recording
from .scene import GROUND_Z, make_plant_scene

SIZES = ("demo", "paper")
#: where the toed-in cameras aim (rig frame): the plant's centre, 0.8 m below the depth camera
AIM_POINT = np.array([0.0, 0.0, 0.80])


def _rot_x(deg: float) -> np.ndarray:
    a = np.radians(deg)
    return np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])


def _rot_z(deg: float) -> np.ndarray:
    a = np.radians(deg)
    return np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])


def _look_at(center_rig: np.ndarray, aim_rig: np.ndarray, roll_deg: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """``R_cam_rig``, ``t_cam_rig`` of a camera at ``center_rig`` whose optical axis passes through
    ``aim_rig``, image x as close to the rig's x as possible, then rolled by ``roll_deg``
    (a real mount is never perfectly square)."""
    z = aim_rig - center_rig
    z = z / np.linalg.norm(z)
    x = np.array([1.0, 0, 0]) - z[0] * z
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    R_cam_rig = _rot_z(roll_deg) @ np.stack([x, y, z])
    return R_cam_rig, -R_cam_rig @ center_rig


def _K(f: float, cx: float, cy: float) -> np.ndarray:
    return np.array([[f, 0, cx], [0, f, cy], [0, 0, 1.0]])


def _scale_K(K: np.ndarray, s: float) -> np.ndarray:
    """Intrinsics of the same lens on a sensor with ``s`` times the pixels per axis
    (pixel centres at integers: c' = (c + 0.5) * s - 0.5)."""
    return _K(K[0, 0] * s, (K[0, 2] + 0.5) * s - 0.5, (K[1, 2] + 0.5) * s - 0.5)


#: Optical blur of the realistic demo's thermal camera: Gaussian sigma in its pixels (rig key
#: ``"blur_px"``; microbolometer lenses are soft, and the mixed-pixel flag widens by it)
THERMAL_BLUR_PX = 1.0
#: Depth noise of the realistic demo: sigma = 1 mm + 0.1 % of the depth (Azure Kinect-like random error)
TOF_DEPTH_NOISE = (0.001, 0.001)


def demo_rig(size: str = "demo", thermal_blur_px: float = 0.0) -> Rig:
    """The synthetic rig: ``ir`` (depth + infrared, 640x576), ``rgb`` (1280x720, or 3840x2160 for
    ``size="paper"``), ``thermal`` (640x480) and ``hyperspectral`` (256x256 x 100 bands, or
    512x512 x 204 bands for ``"paper"``). Geometry and distortion are documented in docs/demo.md.
    ``thermal_blur_px`` > 0 gives the thermal camera an optical blur (rig key ``"blur_px"``).
    """
    if size not in SIZES:
        raise InputError(f"unknown demo size '{size}' (choose {' or '.join(SIZES)})")
    paper = size == "paper"
    cams: list[Camera] = []

    # Time-of-flight depth camera with its infrared image (Azure Kinect NFOV unbinned-like):
    # rational distortion model, as the Kinect's factory calibration uses.
    cams.append(Camera(
        "ir", "infrared", 640, 576, _K(504.2, 321.4, 289.7),
        [0.25, -0.02, 2.1e-4, -1.3e-4, 1.0e-3, 0.33, 5.0e-3, 0.0],
        np.eye(3), np.zeros(3), {"units": "DN"},
    ))

    # Colour camera: 32 mm beside the depth camera and tilted by 6 degrees, like the Azure Kinect's.
    K_rgb = _K(605.3, 638.9, 366.2)
    if paper:
        K_rgb = _scale_K(K_rgb, 3.0)
    R = _rot_x(-6.0) @ _rot_z(0.15)
    C = np.array([-0.032, -0.0015, 0.0040])
    cams.append(Camera(
        "rgb", "rgb", 3840 if paper else 1280, 2160 if paper else 720, K_rgb,
        [0.082, -0.061, 6.0e-4, -4.0e-4, 0.012], R, -R @ C, {},
    ))

    # Thermal camera: 640x480, 32.7 deg horizontal field of view, 12 cm off, toed in.
    f_th = 320.0 / np.tan(np.radians(32.7 / 2))
    R, t = _look_at(np.array([0.118, 0.012, -0.008]), AIM_POINT, roll_deg=0.6)
    cams.append(Camera(
        "thermal", "thermal", 640, 480, _K(f_th, 318.6, 242.1),
        [-0.21, 0.18, 8.0e-4, -5.0e-4, -0.05], R, t,
        {"units": "degC", **({"blur_px": float(thermal_blur_px)} if thermal_blur_px > 0 else {})},
    ))

    # Hyperspectral camera (Specim IQ-like): 31 x 31 degrees, on the other side, toed in.
    n_px = 512 if paper else 256
    f_hs = (n_px / 2) / np.tan(np.radians(31.0 / 2))
    c_hs = (127.8 + 0.5) * (n_px / 256) - 0.5
    bands = np.linspace(397.32, 1003.58, 204) if paper else np.linspace(400.0, 1000.0, 100)
    R, t = _look_at(np.array([-0.125, -0.035, -0.012]), AIM_POINT, roll_deg=-0.8)
    cams.append(Camera(
        "hyperspectral", "hyperspectral", n_px, n_px, _K(f_hs, c_hs, c_hs + 1.1 * n_px / 256),
        [-0.06, 0.04, 3.0e-4, 2.0e-4, 0.0], R, t,
        {"bands": [round(float(b), 2) for b in bands], "units": "reflectance"},
    ))

    return Rig(
        cams, depth_camera="ir", depth_scale=0.001,
        roi_min=np.array([-0.45, -0.45, 0.30]), roi_max=np.array([0.45, 0.45, 1.17]),
        extra={"synthetic": {"size": size, "ground_plane_z": GROUND_Z,
                             "note": "synthetic demo rig of plantreg; ROI max z (1.17) lies 3 cm above the ground plane (1.20)"}},
    )


# ---------------------------------------------------------------------- writing
def _write_envi(hdr: Path, cube: np.ndarray, bands: list[float]) -> None:
    import spectral.io.envi as envi

    envi.save_image(str(hdr), cube, dtype=np.float32, interleave="bsq", force=True,
                    metadata={"wavelength": list(bands), "wavelength units": "nm",
                              "description": "plantreg synthetic demo, reflectance"})


def write_demo(folder: str | Path, size: str = "demo", seed: int = 0, progress: Reporter | None = None,
               *, overwrite: bool = False, calibration: bool = True,
               supersample: int | None = None, clean: bool = False) -> dict[str, Path]:
    """Write the demo to ``folder`` (built beside it under a temporary name, then moved into place):

    ``rig.json``, ``recording/`` (``recording.json``, ``depth.png`` uint16 mm, ``ir.png`` uint16,
    ``rgb.png``, ``thermal.tif`` float32 degC, ``hyperspectral.hdr``/``.img`` ENVI float32),
    ``ground_truth/ir.npz`` (:class:`GroundTruth` for target ``ir``) and ``calibration/`` (the
    synthetic calibration session of this rig; ``calibration=False`` skips it). Returns the paths
    (in ``folder``) by name: ``rig``, ``recording``, ``ground_truth``, ``calibration``.
    ``supersample`` is passed to :func:`render_recording` (1 = quicker, no anti-aliasing).
    By default the recording is *realistic*: the depth map has time-of-flight artefacts (flying
    pixels by footprint mixing, holes on steep surfaces, 1 mm + 0.1 % noise) and the thermal
    camera an optical blur (``THERMAL_BLUR_PX``); ``clean=True`` gives the ideal recording
    (exact depth quantised to 1 mm, sharp images) that the accuracy tests use.
    Raises :class:`InputError` if ``folder`` exists and is not empty, unless ``overwrite``.
    """
    progress = ensure_reporter(progress)
    folder = Path(folder)
    rig = demo_rig(size, thermal_blur_px=0.0 if clean else THERMAL_BLUR_PX)
    depth_noise = (0.0, 0.0) if clean else TOF_DEPTH_NOISE
    with atomic_output_dir(folder, overwrite) as tmp:
        with progress.stage("scene", 0.0, 0.05):
            scene = make_plant_scene(seed)
        rec = render_recording(rig, scene, depth_noise, seed=seed, progress=progress.sub(0.05, 0.6),
                               supersample=supersample, tof=not clean)
        with progress.stage("writing recording", 0.6):
            rig.save(tmp / "rig.json")
            rdir = tmp / "recording"
            rdir.mkdir()
            names = {"ir": "ir.png", "rgb": "rgb.png", "thermal": "thermal.tif", "hyperspectral": "hyperspectral.hdr"}
            write_png(rdir / "depth.png", rec.depth)
            for cam in rig.cameras:
                img = rec.images[cam.name]
                fn = names.get(cam.name, f"{cam.name}.tif")
                if fn.endswith(".hdr"):
                    _write_envi(rdir / fn, img, cam.extra["bands"])
                elif fn.endswith(".png"):
                    write_png(rdir / fn, img)
                else:
                    write_tiff(rdir / fn, img)
            manifest: dict[str, Any] = {
                "depth": "depth.png", "images": {c.name: names.get(c.name, f"{c.name}.tif") for c in rig.cameras},
                "synthetic": {"generator": "plantreg demo", "size": size, "seed": seed, "depth_noise": list(depth_noise),
                              "tof_artefacts": not clean,
                              "leaves": [lf.to_dict() for lf in scene.leaves]},
            }
            atomic_write_text(rdir / "recording.json", json.dumps(manifest, indent=2) + "\n")
            progress(0.7, "writing recording")
        with progress.stage("ground truth", 0.7, 0.8):
            gt = ground_truth(rig, scene, "ir", progress=progress.sub(0.7, 0.8))
            (tmp / "ground_truth").mkdir()
            gt.save(tmp / "ground_truth" / "ir.npz")
        paths = {"rig": folder / "rig.json", "recording": folder / "recording",
                 "ground_truth": folder / "ground_truth" / "ir.npz"}
        if calibration:
            with progress.stage("calibration session", 0.8, 1.0):
                _write_calibration_session(rig, tmp / "calibration", seed, progress.sub(0.8, 1.0))
                paths["calibration"] = folder / "calibration"
        progress(1.0, "demo written")
    return paths


def _write_calibration_session(rig: Rig, folder: Path, seed: int, progress: Reporter) -> None:
    """Synthetic chessboard captures of ``rig`` (rendered by the calibration package)."""
    # imported here: the calibration package is large and only this step needs it
    from ..calibration.synthetic import write_calibration_session

    write_calibration_session(rig, folder, seed=seed, progress=progress)
