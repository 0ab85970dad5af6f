"""The region of interest (ROI) against a plant's depth map: fit it, and check what it cuts off.

The ROI is an axis-aligned box in the rig frame (= depth camera frame, z away from the camera);
its max z is the ground plane: the scene beyond it (the ground, the table, the background) is
not the plant. It must come from a depth map *with the plant in view* -- a box fitted to a
calibration board's pose ends where the board was (e.g. 0.56 m) and registration then keeps one
leaf of a plant standing 0.6-1.2 m away without any other sign of failure.

Fitting: the far surface is found as the 95th percentile of the measured z (the ground or
background fills much of a phenotyping view); what lies more than ``FAR_MARGIN_M`` in front of it
is "the scene", which the fitted ROI contains.

Checking: a rig centres the plant in the depth camera's view, and the plant is what the camera
sees *first* there -- the nearest ``CANOPY_PERCENTILE`` % of the measured depth in the middle of
the view (``CENTRAL_PERCENTILES`` of the viewing directions in x and y) is the plant's top part.
An ROI that leaves most of that out cuts the plant. The check does not judge what lies further away: real rigs show trays, tables, floors,
frames and cables around the plant, which a hand-set ROI rightly drops (on the six
Plant3DImageReg recordings they make up 65-76 % of the measured depth in front of the floor, so
"most of the scene is cut" was true of an ROI that keeps every plant whole).

The far side is checked too: a ground plane (max z) set in or just behind the ground, a table or
the background puts that surface inside the ROI, and registration calls it certain object (the
demo's ground at 1.20 m under the default ROI's 1.20 m: twice as many "object" pixels as lie on
the plant). Nothing of a plant lies within ``GROUND_BAND_M`` in front of a well-set ground plane
(the six Plant3DImageReg ROIs: at most 0.1 % of their measured depth; the default ROI over the
same plants 4-24 %).
"""

from __future__ import annotations

import numpy as np

FAR_PERCENTILE = 95.0
FAR_MARGIN_M = 0.05  # the scene: points this far in front of the far surface, or more
GROUND_CLEARANCE_M = 0.03  # a fitted ground plane sits this far in front of the far surface
CENTRAL_PERCENTILES = (20.0, 80.0)  # the middle of the view: these percentiles of x/z and of y/z
CANOPY_PERCENTILE = 25.0  # the plant's top: the nearest quarter of the measured points there
CUT_WARN_FRACTION = 0.5  # warn when the ROI leaves out more than half of them
GROUND_BAND_M = 0.05  # measured depth this close in front of the ground plane is the ground's
GROUND_WARN_FRACTION = 0.10  # warn when more of the ROI's measured depth lies there


def _finite(points: np.ndarray) -> np.ndarray:
    X = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    return X[np.all(np.isfinite(X), axis=1)]


def scene_points(points: np.ndarray) -> np.ndarray:
    """The measured points (N, 3) in front of the far surface (ground/background) of ``points``
    (..., 3) rig frame, NaN = no measurement."""
    X = _finite(points)
    if not len(X):
        return X
    z_far = np.percentile(X[:, 2], FAR_PERCENTILE)
    return X[X[:, 2] < z_far - FAR_MARGIN_M]


def canopy_points(points: np.ndarray) -> np.ndarray:
    """The plant's top part (N, 3): the nearest CANOPY_PERCENTILE % of the measured points of
    ``points`` (..., 3) rig frame (NaN = no measurement) in the middle of the view, i.e. with x/z
    and y/z both within CENTRAL_PERCENTILES of the measured directions. Frames, cables and
    trays at the edge of the view are not in it, however near they are."""
    X = _finite(points)
    X = X[X[:, 2] > 0]
    if not len(X):
        return X
    central = np.ones(len(X), dtype=bool)
    for a in (X[:, 0] / X[:, 2], X[:, 1] / X[:, 2]):
        lo, hi = np.percentile(a, CENTRAL_PERCENTILES)
        central &= (a >= lo) & (a <= hi)
    X = X[central]
    return X[X[:, 2] <= np.percentile(X[:, 2], CANOPY_PERCENTILE)]


def cut_fraction(points: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> tuple[float, int]:
    """Fraction of the canopy's points (see :func:`canopy_points`) outside the ROI [lo, hi] (3,),
    and their number; (0.0, 0) without measured depth."""
    C = canopy_points(points)
    if not len(C):
        return 0.0, 0
    inside = np.all((C >= np.asarray(lo, float)) & (C <= np.asarray(hi, float)), axis=1)
    return float(1.0 - inside.mean()), int(len(C))


def cut_warning(points: np.ndarray, lo: np.ndarray, hi: np.ndarray, advice: bool = True) -> str | None:
    """A sentence when the ROI leaves out most of the canopy (more than CUT_WARN_FRACTION), else
    None. ``advice``: end with what to do about it."""
    frac, n = cut_fraction(points, lo, hi)
    if n < 100 or frac <= CUT_WARN_FRACTION:
        return None
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    z = np.percentile(canopy_points(points)[:, 2], [5, 95])
    return (f"the ROI (min {np.round(lo, 3).tolist()}, max {np.round(hi, 3).tolist()} m, ground plane at "
            f"z = {hi[2]:.2f} m) leaves out {100 * frac:.0f} % of the plant's top (the nearest measured depth in "
            f"the middle of the view, z = {z[0]:.2f}-{z[1]:.2f} m): the registration covers only part of the plant"
            + (". Set the rig's ROI from a depth map of a plant recording (calibration wizard, page 7)" if advice else ""))


def ground_share(points: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> tuple[float, int, np.ndarray]:
    """Share of the measured points of ``points`` (..., 3) rig frame inside the ROI [lo, hi] (3,)
    that lie within GROUND_BAND_M in front of its ground plane z = hi[2], the number of measured
    points inside the ROI, and those near points (M, 3)."""
    X = _finite(points)
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    inside = X[np.all((X >= lo) & (X <= hi), axis=1)]
    if not len(inside):
        return 0.0, 0, inside
    near = inside[inside[:, 2] > hi[2] - GROUND_BAND_M]
    return float(len(near) / len(inside)), int(len(inside)), near


def ground_warning(points: np.ndarray, lo: np.ndarray, hi: np.ndarray, advice: bool = True) -> str | None:
    """A sentence when the ROI's ground plane lies in (or just behind) a measured surface: more
    than GROUND_WARN_FRACTION of the measured depth inside the ROI within GROUND_BAND_M in front
    of it (see :func:`ground_share`); else None, and None when the ROI cuts the plant (then the
    surface at its ground plane is the plant's: :func:`cut_warning` says so). ``advice``: end with
    what to do about it."""
    frac, n, _near = ground_share(points, lo, hi)
    if n < 100 or frac <= GROUND_WARN_FRACTION or cut_warning(points, lo, hi) is not None:
        return None
    hi = np.asarray(hi, float)
    text = (f"the ROI's ground plane (max z = {hi[2]:.2f} m) lies in a measured surface: {100 * frac:.0f} % of the "
            f"measured depth inside the ROI is within {100 * GROUND_BAND_M:.0f} cm in front of it (the ground, a "
            "table or the background), and registration takes it as the plant (certain object)")
    if advice:
        text += (". Set max z a few centimetres in front of the ground: calibration wizard page 7, "
                 "'Load plant depth map'")
    return text


def fit_roi(points: np.ndarray, margin_m: float = 0.02) -> tuple[np.ndarray, np.ndarray]:
    """An ROI for a plant depth map ``points`` (..., 3): x and y span the 1st-99th percentiles of
    every measured point (the whole view of the ground, so that leaves moving between
    recordings stay inside), min z is the scene's 1st percentile minus ``margin_m``, max z (the
    ground plane) lies GROUND_CLEARANCE_M in front of the far surface. Returns (lo (3,), hi (3,))."""
    X = _finite(points)
    if len(X) < 10:
        raise ValueError("the depth map has fewer than 10 measured points")
    S = scene_points(X)
    lo_xy = np.percentile(X[:, :2], 1, axis=0) - margin_m
    hi_xy = np.percentile(X[:, :2], 99, axis=0) + margin_m
    z_far = float(np.percentile(X[:, 2], FAR_PERCENTILE))
    z_min = float(np.percentile(S[:, 2] if len(S) else X[:, 2], 1)) - margin_m
    z_max = z_far - GROUND_CLEARANCE_M if len(S) else float(np.percentile(X[:, 2], 99)) + margin_m
    return np.array([lo_xy[0], lo_xy[1], max(z_min, 0.0)]), np.array([hi_xy[0], hi_xy[1], z_max])
