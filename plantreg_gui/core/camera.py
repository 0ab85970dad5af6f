"""Pinhole camera with OpenCV distortion, posed in the rig frame.

Conventions (stated once, used everywhere):

* OpenCV pinhole model and distortion coefficients (any length OpenCV accepts: 4, 5, 8, 12, 14).
* Pixel centres at integer coordinates: pixel (col=u, row=v) covers [u-0.5, u+0.5].
* Metres.
* ``X_cam = R_cam_rig @ X_rig + t_cam_rig``; the rig frame is the depth camera's frame.
* Camera frame: x right, y down, z forward (optical axis).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np

from . import modality as _modality

#: Iteration criteria for undistortion: OpenCV's default (5 iterations) leaves errors of
#: tenths of a pixel near the border of strongly distorted lenses.
_UNDISTORT_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-12)


@dataclass
class Camera:
    """One camera of the rig.

    ``K`` (3, 3), ``dist`` (n,), ``R_cam_rig`` (3, 3), ``t_cam_rig`` (3,), all float64.
    ``extra`` keeps unknown keys of the rig file so that saving does not lose them.
    """

    name: str
    modality: str
    width: int
    height: int
    K: np.ndarray
    dist: np.ndarray = field(default_factory=lambda: np.zeros(5))
    R_cam_rig: np.ndarray = field(default_factory=lambda: np.eye(3))
    t_cam_rig: np.ndarray = field(default_factory=lambda: np.zeros(3))
    extra: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.K = np.asarray(self.K, dtype=np.float64).reshape(3, 3)
        self.dist = np.asarray(self.dist, dtype=np.float64).ravel()
        self.R_cam_rig = np.asarray(self.R_cam_rig, dtype=np.float64).reshape(3, 3)
        self.t_cam_rig = np.asarray(self.t_cam_rig, dtype=np.float64).reshape(3)
        self.width = int(self.width)
        self.height = int(self.height)

    # ------------------------------------------------------------------ geometry
    @property
    def shape(self) -> tuple[int, int]:
        """(height, width), numpy order."""
        return (self.height, self.width)

    @property
    def center_rig(self) -> np.ndarray:
        """Optical centre in the rig frame, (3,)."""
        return -self.R_cam_rig.T @ self.t_cam_rig

    @property
    def R_rig_cam(self) -> np.ndarray:
        return self.R_cam_rig.T

    @property
    def rvec(self) -> np.ndarray:
        """Rodrigues vector of ``R_cam_rig``, (3,)."""
        return cv2.Rodrigues(self.R_cam_rig)[0].ravel()

    @property
    def normalization(self) -> float:
        """The paper's error normalisation factor 1000 / sqrt(h * w)."""
        return 1000.0 / float(np.sqrt(self.height * self.width))

    def to_cam(self, X_rig: np.ndarray) -> np.ndarray:
        """Rig-frame points (N, 3) -> camera-frame points (N, 3)."""
        return np.asarray(X_rig, dtype=np.float64) @ self.R_cam_rig.T + self.t_cam_rig

    def to_rig(self, X_cam: np.ndarray) -> np.ndarray:
        """Camera-frame points (N, 3) -> rig-frame points (N, 3)."""
        return (np.asarray(X_cam, dtype=np.float64) - self.t_cam_rig) @ self.R_cam_rig

    def project(self, X_rig: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Project rig-frame points (N, 3) through the distortion model.

        Returns ``uv`` (N, 2) distorted pixel coordinates and ``z`` (N,) depth in the camera
        frame. Points with ``z <= 0`` are behind the camera: their ``uv`` is NaN.
        """
        X_rig = np.asarray(X_rig, dtype=np.float64).reshape(-1, 3)
        z = self.to_cam(X_rig)[:, 2]
        if len(X_rig) == 0:
            return np.zeros((0, 2)), z
        uv, _ = cv2.projectPoints(X_rig, self.rvec, self.t_cam_rig, self.K, self.dist)
        uv = uv.reshape(-1, 2)
        uv[~(z > 0)] = np.nan
        return uv, z

    def in_image(self, uv: np.ndarray, margin: float = 0.0) -> np.ndarray:
        """Mask (N,) of pixel coordinates inside the image (pixel-centre convention)."""
        u, v = uv[:, 0], uv[:, 1]
        with np.errstate(invalid="ignore"):
            return (
                (u >= -0.5 + margin)
                & (u <= self.width - 0.5 - margin)
                & (v >= -0.5 + margin)
                & (v <= self.height - 0.5 - margin)
            )

    def undistort_normalized(self, uv: np.ndarray) -> np.ndarray:
        """Distorted pixels (N, 2) -> ideal normalised coordinates (N, 2) (x/z, y/z)."""
        uv = np.ascontiguousarray(np.asarray(uv, dtype=np.float64).reshape(-1, 1, 2))
        if len(uv) == 0:
            return np.zeros((0, 2))
        xy = cv2.undistortPoints(uv, self.K, self.dist, None, np.eye(3), criteria=_UNDISTORT_CRITERIA)
        return xy.reshape(-1, 2)

    def pixel_grid(self) -> np.ndarray:
        """All pixel centres, row-major, (H*W, 2) as (u, v)."""
        v, u = np.mgrid[0 : self.height, 0 : self.width]
        return np.stack([u.ravel(), v.ravel()], axis=1).astype(np.float64)

    def rays_cam(self, uv: np.ndarray | None = None) -> np.ndarray:
        """Viewing directions in the camera frame with z = 1, (N, 3); all pixels if ``uv`` is None."""
        uv = self.pixel_grid() if uv is None else uv
        xy = self.undistort_normalized(uv)
        return np.concatenate([xy, np.ones((len(xy), 1))], axis=1)

    def rays_rig(self, uv: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Rays through pixels in the rig frame: origin (3,) and unit directions (N, 3)."""
        d_cam = self.rays_cam(uv)
        d_rig = d_cam @ self.R_cam_rig  # R_rig_cam @ d for each row
        d_rig /= np.linalg.norm(d_rig, axis=1, keepdims=True)
        return self.center_rig, d_rig

    # ------------------------------------------------------------------ serialisation
    _KNOWN = ("name", "modality", "width", "height", "K", "dist", "R", "t")

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {
            "name": self.name,
            "modality": self.modality,
            "width": self.width,
            "height": self.height,
            "K": self.K.tolist(),
            "dist": self.dist.tolist(),
            "R": self.R_cam_rig.tolist(),
            "t": self.t_cam_rig.tolist(),
        }
        d.update(self.extra)
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any], key: str = "camera") -> "Camera":
        """Build from a rig-file entry; raises ``ValueError`` with a readable message that starts
        with ``key`` (the entry's place in the file, e.g. ``cameras[2]``). Types and the physical
        sanity bounds are checked by :mod:`.validate` (documented there and in docs/errors.md)."""
        from . import validate as v

        if not isinstance(d, dict):
            raise ValueError(f"{key} must be an object {{\"name\": ..., \"width\": ...}}, got {v.show(d)}")
        missing = [k for k in ("name", "width", "height", "K") if k not in d]
        if missing:
            raise ValueError(f"{key} lacks {', '.join(missing)}")
        name = v.camera_name(d["name"], f"{key}.name")
        modality = v.string(d.get("modality", "unknown"), f"{key}.modality")
        width = v.positive_int(d["width"], f"{key}.width", v.MAX_SIDE)
        height = v.positive_int(d["height"], f"{key}.height", v.MAX_SIDE)
        K = v.number_array(d["K"], f"{key}.K", (3, 3), " (3 x 3 camera matrix)")
        dist = v.number_array(d.get("dist", [0, 0, 0, 0, 0]), f"{key}.dist").ravel()
        R = v.number_array(d.get("R", np.eye(3).tolist()), f"{key}.R", (3, 3), " (3 x 3 rotation)")
        t = v.number_array(d.get("t", [0, 0, 0]), f"{key}.t", (3,), " (metres)")
        v.check_intrinsics(K, width, height, key)
        v.check_distortion(dist, K, width, height, key)
        v.check_rotation(R, key)
        v.check_translation(t, key)
        extra = {k: val for k, val in d.items() if k not in cls._KNOWN}
        # canonical modality name ('visible' -> 'rgb', 'lwir' -> 'thermal'): nothing downstream re-interprets it
        return cls(name, _modality.canonical(modality), width, height, K, dist if dist.size else np.zeros(5), R, t, extra)
