"""Reading the public Plant3DImageReg recordings (Stumpe et al.) for inspection.

Pure numpy/OpenCV, no Qt (the workspace reads it on a worker; scripts can use it too).

The data set (``../shared/data/plant3dimagereg``) is laid out as one folder per image kind and
one file per plant (``lidar_depthmap_np/01grapevine.npy``, ``infra_np/...``, ``thermal_np_01/...``,
``hs/...png``, ``hs_pca_01/...png``). It ships **no calibration**: the cameras' intrinsics and
extrinsics are unknown, so the images cannot be registered with plantreg until someone
calibrates that rig. What can be inspected without calibration: the raw images in their units
and the depth camera's own point cloud, back-projected with the *nominal* Azure Kinect NFOV
unbinned intrinsics (640 x 576 pixels, 75 x 65 degree field of view, no distortion) — nominal
figures, not a calibration, so the cloud's scale and shape are approximate.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..camera.camera import Camera
from ..geometry.depth import back_project as _back_project_hw3
from ..geometry.depth import points_and_pixels, to_metres
from ..errors import InputError
from ..io.imageio import read_image

#: folder -> (image name shown to the user, unit, modality)
KINDS: dict[str, tuple[str, str, str]] = {
    "lidar_depthmap_np": ("depth", "mm", "depth"),
    "infra_np": ("ir", "", "infrared"),
    "thermal_np_01": ("thermal", "°C", "thermal"),
    "hs": ("hs render", "", "rgb"),
    "hs_pca_01": ("hs pca", "", "rgb"),
}
DEPTH_FOLDER = "lidar_depthmap_np"

#: Nominal Azure Kinect NFOV unbinned depth mode (Microsoft's hardware specification).
NOMINAL_SIZE = (640, 576)          # width, height
NOMINAL_FOV_DEG = (75.0, 65.0)     # horizontal, vertical

NO_CALIBRATION = (
    "No calibration ships with this data set: registration needs a rig file with the cameras' "
    "intrinsics and extrinsics, which are unknown for this rig. Showing the raw images and the "
    "depth camera's point cloud back-projected with NOMINAL Azure Kinect NFOV intrinsics "
    "(640x576, 75x65 deg field of view, no distortion) — approximate, not calibrated."
)


def is_dataset(folder: str | Path) -> bool:
    """True when ``folder`` looks like the Plant3DImageReg data set (has the depth-map folder)."""
    return (Path(folder) / DEPTH_FOLDER).is_dir()


def list_plants(folder: str | Path) -> list[str]:
    """Plant names (file stems of the depth maps), sorted: ``['01grapevine', ...]``."""
    folder = Path(folder)
    if not is_dataset(folder):
        raise InputError(f"not the Plant3DImageReg data set (no '{DEPTH_FOLDER}' folder inside)", folder)
    plants = sorted(p.stem for p in (folder / DEPTH_FOLDER).glob("*.npy"))
    if not plants:
        raise InputError(f"no depth maps (*.npy) in '{DEPTH_FOLDER}'", folder / DEPTH_FOLDER)
    return plants


def nominal_intrinsics(width: int = NOMINAL_SIZE[0], height: int = NOMINAL_SIZE[1],
                       fov_deg: tuple[float, float] = NOMINAL_FOV_DEG) -> np.ndarray:
    """Pinhole K (3, 3) from a field of view; principal point at the image centre
    (pixel centres at integer coordinates, so the centre is ((W-1)/2, (H-1)/2))."""
    fx = (width / 2.0) / math.tan(math.radians(fov_deg[0]) / 2.0)
    fy = (height / 2.0) / math.tan(math.radians(fov_deg[1]) / 2.0)
    return np.array([[fx, 0.0, (width - 1) / 2.0], [0.0, fy, (height - 1) / 2.0], [0.0, 0.0, 1.0]])


def back_project(depth_mm: np.ndarray, K: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Depth map (H, W) in millimetres -> points (N, 3) in metres in the depth camera frame
    (x right, y down, z forward) and their flat pixel indices (N,). Pixels with 0 depth are skipped.
    A pinhole camera (no distortion) through the core's one back-projection."""
    h, w = depth_mm.shape
    cam = Camera("depth", "depth", w, h, np.asarray(K, dtype=np.float64), np.zeros(5), np.eye(3), np.zeros(3))
    return points_and_pixels(_back_project_hw3(cam, to_metres(depth_mm, 0.001)))


@dataclass
class Plant3DRecording:
    """One plant of the data set.

    ``images[name]`` raw arrays (depth uint16 mm (576, 640); ir uint16 (576, 640); thermal float
    degC (480, 640); renders uint8 (512, 512, 3)); ``units[name]``, ``modalities[name]``.
    ``points`` (N, 3) float32 metres in the depth camera frame (nominal intrinsics),
    ``point_pixels`` (N,) flat indices into the depth map, ``K`` the nominal intrinsics used.
    """

    folder: Path
    plant: str
    images: dict[str, np.ndarray]
    units: dict[str, str]
    modalities: dict[str, str]
    points: np.ndarray
    point_pixels: np.ndarray
    K: np.ndarray
    missing: list[str] = field(default_factory=list)
    note: str = NO_CALIBRATION

    @property
    def depth_shape(self) -> tuple[int, int]:
        return self.images["depth"].shape[:2]


def load_plant(folder: str | Path, plant: str, progress=None) -> Plant3DRecording:
    """Read every image kind of one plant and back-project its depth map (nominal intrinsics).

    Raises :class:`InputError` if the depth map is missing or not 2-D; other kinds that are
    missing are listed in ``missing`` (the data set lacks e.g. the RGB images)."""
    folder = Path(folder)
    list_plants(folder)  # validates the layout
    images: dict[str, np.ndarray] = {}
    units: dict[str, str] = {}
    modalities: dict[str, str] = {}
    missing: list[str] = []
    for i, (sub, (name, unit, modality)) in enumerate(KINDS.items()):
        if progress is not None:
            progress(i / (len(KINDS) + 1), f"reading {sub}/{plant}")
        matches = sorted((folder / sub).glob(f"{plant}.*")) if (folder / sub).is_dir() else []
        if not matches:
            if sub == DEPTH_FOLDER:
                raise InputError(f"no depth map for plant '{plant}'", folder / sub)
            missing.append(sub)
            continue
        images[name] = read_image(matches[0])
        units[name] = unit
        modalities[name] = modality
    depth = images["depth"]
    if depth.ndim != 2:
        raise InputError(f"depth map must be single-channel, got shape {depth.shape}", folder / DEPTH_FOLDER)
    h, w = depth.shape
    K = nominal_intrinsics(w, h)  # the FOV is that of the NFOV mode whatever the size
    if progress is not None:
        progress(len(KINDS) / (len(KINDS) + 1), "back-projecting the depth map (nominal intrinsics)")
    points, pix = back_project(depth, K)
    return Plant3DRecording(folder, plant, images, units, modalities, points, pix, K, missing)
