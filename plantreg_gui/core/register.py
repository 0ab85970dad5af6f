"""Registration engine: depth mesh -> target rays -> source cameras -> registered images + cases.

CONTRACT (filled in by the registration-engine work; signatures are binding for the GUI/CLI).

Case codes per target pixel and source camera (``cases[source]``, uint8):
  0 = P6 certain background (target ray hits neither mesh)
  1 = P1 legitimate
  2 = P2 occlusion (a ray from the source camera towards the hit point meets the object mesh first)
  3 = P3.1 incoming uncertain (the target ray meets the uncertainty mesh before the object mesh)
  4 = P3.2 outgoing uncertain (the source ray meets the uncertainty mesh before the point)
  5 = P5 uncertain object area with no object-mesh hit behind
  6 = hit outside the source image or behind the source camera
Area codes (target only, ``area``): 4 = P4 certain object, 5 = P5 uncertain object area, 6 = P6 background.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .progress import Reporter
from .recording import Recording
from .rig import Rig

CASE_BACKGROUND, CASE_P1, CASE_P2, CASE_P31, CASE_P32, CASE_P5, CASE_OUTSIDE = 0, 1, 2, 3, 4, 5, 6
AREA_P4, AREA_P5, AREA_P6 = 4, 5, 6

CASE_NAMES = {
    0: "P6 background", 1: "P1 legitimate", 2: "P2 occluded", 3: "P3.1 incoming uncertain",
    4: "P3.2 outgoing uncertain", 5: "P5 uncertain area", 6: "outside source",
}
AREA_NAMES = {4: "P4 certain object", 5: "P5 uncertain object", 6: "P6 certain background"}


@dataclass
class RegistrationParams:
    edge_angle_deg: float = 15.0        # mesh edge cut (see mesh.py for the geometry)
    occlusion_tol_m: float = 0.002      # a source-ray hit this much before the point counts as occluding
    roi_min: np.ndarray | None = None   # override the rig's ROI (3,) metres
    roi_max: np.ndarray | None = None

    def to_dict(self) -> dict[str, Any]:
        return {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in self.__dict__.items()}


@dataclass
class RegistrationResult:
    """All arrays are in the target camera's pixel grid, (H, W[, ...]).

    ``points_rig`` (H, W, 3) float32: first object-mesh hit of each target ray, NaN if none.
    ``registered[cam]`` (H, W) or (H, W, B) float32, NaN where not mapped, for every camera incl. the target.
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

    @property
    def shape(self) -> tuple[int, int]:
        return self.area.shape  # type: ignore[return-value]

    def case_counts(self) -> dict[str, dict[int, int]]:
        return {cam: {int(k): int(v) for k, v in zip(*np.unique(c, return_counts=True))}
                for cam, c in self.cases.items()}


class Registrar:
    """Holds the meshes and ray-casting scenes of one recording so that registering to another
    target reuses them. Build once per (rig, recording, params); call :meth:`register` per target.
    """

    def __init__(self, rig: Rig, recording: Recording, params: RegistrationParams | None = None):
        raise NotImplementedError

    def prepare(self, progress: Reporter | None = None) -> None:
        """Build object mesh, uncertainty mesh and Open3D scenes (idempotent)."""
        raise NotImplementedError

    def register(self, target: str, progress: Reporter | None = None) -> RegistrationResult:
        raise NotImplementedError


def register(rig: Rig, recording: Recording, target: str, params: RegistrationParams | None = None,
             progress: Reporter | None = None) -> RegistrationResult:
    """One-shot convenience: ``Registrar(rig, recording, params).register(target, progress)``."""
    return Registrar(rig, recording, params).register(target, progress)
