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
        """Project rig-frame points (N, 3) through the distortion model: the one projection of
        plantreg (OpenCV's model, evaluated vectorised in numpy: :func:`distort_normalized`;
        OpenCV's ``projectPoints`` for sensor-tilt models).

        Returns ``uv`` (N, 2) float64 distorted pixel coordinates and ``z`` (N,) depth in the
        camera frame. ``uv`` is NaN for points with ``z <= 0`` (behind the camera) and for
        non-finite points.
        """
        X_rig = np.asarray(X_rig).reshape(-1, 3)
        if len(X_rig) == 0:
            return np.zeros((0, 2)), np.zeros(0)
        if _has_tilt(self):
            X_rig = X_rig.astype(np.float64)
            z = self.to_cam(X_rig)[:, 2]
            uv, _ = cv2.projectPoints(X_rig, self.rvec, self.t_cam_rig, self.K, self.dist)
            uv = uv.reshape(-1, 2)
            uv[~(z > 0)] = np.nan
            return uv, z
        Xc = X_rig.astype(np.float64) @ self.R_cam_rig.T + self.t_cam_rig
        z = Xc[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            iz = 1.0 / z
            u, v = distort_normalized(self, Xc[:, 0] * iz, Xc[:, 1] * iz)
        uv = np.stack([u, v], axis=1)
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
        from .. import validate as v

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
        v.camera_px_keys(d, key)
        extra = {k: val for k, val in d.items() if k not in cls._KNOWN}
        # canonical modality name ('visible' -> 'rgb', 'lwir' -> 'thermal'): nothing downstream re-interprets it
        return cls(name, _modality.canonical(modality), width, height, K, dist if dist.size else np.zeros(5), R, t, extra)


# ---------------------------------------------------------------------------- the lens model
#: Elements per vectorised step of the camera polynomials (keeps temporaries in cache).
_CHUNK = 1 << 16


def _dist14(cam: Camera) -> np.ndarray:
    d = np.zeros(14)
    d[: min(14, cam.dist.size)] = cam.dist[:14]
    return d


def _has_tilt(cam: Camera) -> bool:
    d = _dist14(cam)
    return bool(d[12] != 0 or d[13] != 0)


def distort_normalized(cam: Camera, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Ideal normalised coordinates (x/z, y/z), (N,) each -> distorted pixel coordinates (u, v),
    float64. Evaluated in cache-sized chunks (the polynomial is memory-bound on big arrays)."""
    n = len(x)
    if n <= _CHUNK:
        return _distort(cam, x, y)
    u = np.empty(n)
    v = np.empty(n)
    for a in range(0, n, _CHUNK):
        u[a : a + _CHUNK], v[a : a + _CHUNK] = _distort(cam, x[a : a + _CHUNK], y[a : a + _CHUNK])
    return u, v


def _distort(cam: Camera, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """OpenCV's model (radial k1..k6 rational, tangential p1 p2, thin prism s1..s4; like
    ``cv2.projectPoints`` the skew K[0, 1] is ignored). Sensor tilt (tauX, tauY) is not
    handled here: callers fall back to OpenCV for tilted models (see :meth:`Camera.project`).
    """
    k1, k2, p1, p2, k3, k4, k5, k6, s1, s2, s3, s4 = _dist14(cam)[:12]
    K = cam.K
    x2, y2, xy = x * x, y * y, x * y
    r2 = x2 + y2
    radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
    if k4 or k5 or k6:
        radial = radial / (1 + r2 * (k4 + r2 * (k5 + r2 * k6)))
    xd = x * radial + 2 * p1 * xy + p2 * (r2 + 2 * x2)
    yd = y * radial + p1 * (r2 + 2 * y2) + 2 * p2 * xy
    if s1 or s2 or s3 or s4:  # thin prism: rare; its array passes are skipped on hot paths (refine's cost)
        r4 = r2 * r2
        xd = xd + s1 * r2 + s2 * r4
        yd = yd + s3 * r2 + s4 * r4
    return K[0, 0] * xd + K[0, 2], K[1, 1] * yd + K[1, 2]
