"""The registration's parameters (with their ranges: :meth:`RegistrationParams.validate`, the one
place they are checked) and its result.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..camera.rig import Rig
from ..errors import InputError

@dataclass(frozen=True)
class Limit:
    """The range of one numeric parameter: ``lo`` .. ``hi`` in the parameter's unit, each end
    included unless ``open_lo`` / ``open_hi``; ``odd`` integers only; ``unit`` and ``scale`` say
    how people see it (``value * scale`` in ``unit``: metres shown in mm)."""

    lo: float
    hi: float
    unit: str = ""
    scale: float = 1.0
    open_lo: bool = False
    open_hi: bool = False
    odd: bool = False

    def contains(self, v: float) -> bool:
        if not np.isfinite(v):
            return False
        if v < self.lo or v > self.hi or (self.open_lo and v == self.lo) or (self.open_hi and v == self.hi):
            return False
        return not self.odd or (float(v).is_integer() and int(v) % 2 == 1)

    def describe(self) -> str:
        lo, hi = self.lo * self.scale, self.hi * self.scale
        unit = f" {self.unit}" if self.unit else ""
        if self.odd:
            return f"an odd number from {lo:g} to {hi:g}{unit}"
        if self.open_lo or self.open_hi:
            return f"between {lo:g} and {hi:g}{unit}"  # an open end: "between" excludes it
        return f"from {lo:g} to {hi:g}{unit}"


#: The one place the parameters' ranges are stated: :meth:`RegistrationParams.validate` checks
#: them, the command line's options and the GUI's spin boxes take their bounds from here.
LIMITS: dict[str, Limit] = {
    "edge_angle_deg": Limit(0.5, 89.5, "degrees"),
    "occlusion_tol_m": Limit(0.0, 0.05, "mm", scale=1000.0),
    "uncertainty_tol_m": Limit(0.0, 0.05, "mm", scale=1000.0),
    "boundary_px": Limit(0.0, 10.0, "depth pixels"),
    "flying_jump_rel": Limit(0.0, 1.0, "(a fraction of the depth)", open_lo=True, open_hi=True),
    "denoise_size": Limit(3, 15, "depth pixels", odd=True),
    "denoise_tol_rel": Limit(0.0, 1.0, "(a fraction of the depth)", open_lo=True, open_hi=True),
    "mixed_radius_px": Limit(0.0, 50.0, "source pixels"),
}


@dataclass
class RegistrationParams:
    edge_angle_deg: float = 15.0        # mesh edge cut (see mesh.py for the geometry)
    occlusion_tol_m: float = 0.002      # a source-ray hit this much before the point counts as occluding
    roi_min: np.ndarray | None = None   # override the rig's ROI (3,) metres
    roi_max: np.ndarray | None = None
    uncertainty_tol_m: float = 0.002    # an uncertainty-mesh hit this much before the point counts (P3.1, P3.2)
    boundary_px: float = 0.5            # skirt around the object mesh's boundary, depth pixels (0 = none)
    # ToF clean-up before meshing (core/geometry/depthfilter.py, docs/registration.md section 1a)
    flying_filter: bool = True          # remove flying pixels (depth between two surfaces)
    flying_jump_rel: float = 0.01       # a depth jump counts above this fraction of the depth (1 cm at 1 m)
    flying_repair: bool = True          # move flying pixels onto the surface they mostly saw (False: remove)
    fill_holes: bool = True             # fill holes between two measured pixels of one surface (steep flanks)
    denoise: bool = True                # edge-preserving same-surface plane fit
    denoise_size: int = 3               # window of the plane fit, depth pixels (odd; 5 = smoother, 3x slower)
    denoise_tol_rel: float = 0.01       # same surface: |dz| <= this fraction of the depth
    mixed_radius_px: float = 1.0        # mixed-pixel flag: source px around a silhouette (+ 2 x camera blur_px)

    def validate(self, names: dict[str, str] | None = None) -> "RegistrationParams":
        """``self`` if every numeric parameter lies in its range (:data:`LIMITS`), else
        :class:`InputError` naming the first one out of range. ``names`` maps a field to the name
        the user knows it by (a command-line option, a GUI label); default: the field name."""
        for key, lim in LIMITS.items():
            v = getattr(self, key)
            if not lim.contains(float(v)):
                name = (names or {}).get(key, key)
                shown = float(v) * lim.scale
                raise InputError(f"{name} must be {lim.describe()}, got {shown:g}")
        return self

    def to_dict(self) -> dict[str, Any]:
        return {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in self.__dict__.items()}

    def roi(self, rig: Rig) -> tuple[np.ndarray, np.ndarray]:
        lo = rig.roi_min if self.roi_min is None else np.asarray(self.roi_min, dtype=np.float64)
        hi = rig.roi_max if self.roi_max is None else np.asarray(self.roi_max, dtype=np.float64)
        return lo, hi


@dataclass
class RegistrationResult:
    """All arrays are in the target camera's pixel grid, (H, W[, ...]).

    ``points_rig`` (H, W, 3) float32: first object-mesh hit of each target ray, NaN if none.
    ``registered[cam]`` (H, W) or (H, W, B) float32, NaN where not mapped, for every camera incl. the target;
    above :data:`DENSE_LIMIT_BYTES` (cubes: see :func:`keep_at_hits`) a :class:`~.hits.HitImage` (values at the hits only; behaves
    like the array: ``np.asarray``, indexing, ``.shape``).
    ``source_uv[cam]`` (H, W, 2) float32 distorted source pixel coordinates of the hit (NaN if none).
    ``cases[cam]`` (H, W) uint8 for every camera except the target. ``area`` (H, W) uint8.
    ``timings`` stage name -> seconds.
    """

    target: str
    points_rig: np.ndarray
    area: np.ndarray
    registered: dict[str, np.ndarray]
    source_uv: dict[str, np.ndarray]
    cases: dict[str, np.ndarray]
    params: RegistrationParams
    timings: dict[str, float] = field(default_factory=dict)
    stats: dict[str, Any] = field(default_factory=dict)
    #: (H_depth, W_depth) bool: depth pixels removed as flying before meshing (depth camera's grid)
    flying: np.ndarray | None = None
    #: source camera -> (H, W) bool: P1 pixels whose footprint in the source reaches across a
    #: silhouette of the object mesh (see core/registration/mixed.py); statistics can exclude them
    mixed: dict[str, np.ndarray] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)  # sentences for the user (e.g. core.roi.cut_warning)

    @property
    def shape(self) -> tuple[int, int]:
        return self.area.shape  # type: ignore[return-value]

    def case_counts(self) -> dict[str, dict[int, int]]:
        # bincount, not np.unique: no sort of H x W codes per camera
        out = {}
        for cam, c in self.cases.items():
            counts = np.bincount(np.asarray(c, dtype=np.uint8).ravel())
            out[cam] = {int(k): int(counts[k]) for k in np.flatnonzero(counts)}
        return out
