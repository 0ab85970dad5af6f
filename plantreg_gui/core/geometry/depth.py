"""Depth maps: the one conversion to metres and the one back-projection.

A depth map is stored in the camera's raw units (Azure Kinect: uint16 millimetres); ``scale`` is
metres per unit (``rig.depth_scale``). 0, negative and NaN mean "no measurement". Everything that
needs depth in metres or millimetres, or 3D points from a depth map, goes through here.
"""

from __future__ import annotations

import numpy as np

from .mesh import backproject_depth as back_project  # noqa: F401 (the one back-projection, re-exported)


def to_metres(raw: np.ndarray, scale: float) -> np.ndarray:
    """Raw depth (H, W) -> metres, float32 (H, W); NaN where there is no measurement."""
    with np.errstate(over="ignore", invalid="ignore"):
        d = np.asarray(raw).astype(np.float32) * np.float32(scale)
        d[~(np.isfinite(d) & (d > 0))] = np.nan  # an infinite depth is no measurement either
    return d


def to_millimetres(raw: np.ndarray, scale: float) -> np.ndarray:
    """Raw depth (H, W) -> millimetres, float32 (H, W); NaN where there is no measurement."""
    return to_metres(raw, scale * 1000.0)


def points_and_pixels(points_hw3: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(H, W, 3) points with NaN where none -> finite points (N, 3) float32 and their flat pixel indices (N,)."""
    flat = np.asarray(points_hw3).reshape(-1, 3)
    pix = np.flatnonzero(np.all(np.isfinite(flat), axis=1))
    return np.ascontiguousarray(flat[pix], dtype=np.float32), pix


__all__ = ["to_metres", "to_millimetres", "back_project", "points_and_pixels"]
