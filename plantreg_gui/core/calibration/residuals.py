"""What the corner review draws over an image once it is calibrated: each corner's residual
vector (where the calibrated model puts the corner minus where it was detected), and the image
and points undistorted with the calibrated model (a straight board edge must come out straight).

The reprojection uses the camera's calibrated intrinsics and the view's *own* board pose (as
``CameraCalibration.per_view_px`` and MATLAB's Camera Calibrator), so the mean length of the
vectors is the view's error on the Intrinsics page.
"""

from __future__ import annotations

import cv2
import numpy as np

from .board import Board
from .calibrate import Calibration, _per_view_errors, flipped_detection
from .detection import Detection


def view_residuals(cal: Calibration, det: Detection, board: Board) -> tuple[np.ndarray, np.ndarray] | None:
    """Detected corners (N, 2) px of ``det`` (a found view of a calibrated camera) and their
    residual vectors (N, 2) px = reprojected - detected, in the detection's own corner order;
    None if the camera is not calibrated or the view has fewer than 4 corners."""
    cc = cal.intrinsics.get(det.camera)
    if cc is None or det.corners is None or len(det.corners) < 4:
        return None
    key = (det.pose, det.camera)
    view = flipped_detection(det) if key in cal.flipped else det  # the order the calibration used
    init = {det.pose: cal.view_board_cam[key]} if key in cal.view_board_cam else None
    _px, _poses, resid, _rms = _per_view_errors(cc.K, cc.dist, {det.pose: view}, board, init)
    r = resid[det.pose]
    if key in cal.flipped:
        r = r[::-1]  # flipped_detection reverses the corner order
    return np.asarray(det.corners, np.float64).reshape(-1, 2), np.asarray(r, np.float64)


def drawing_scale(residuals: np.ndarray, spacing_px: float) -> float:
    """A round factor (1, 2, 5 x 10^k) that draws the view's typical (median) residual vector
    at about 40 % of the corner spacing ``spacing_px``: sub-pixel vectors become visible and
    their directions comparable."""
    med = float(np.median(np.linalg.norm(np.asarray(residuals, float).reshape(-1, 2), axis=1)))
    if not np.isfinite(med) or med <= 0:
        return 1.0
    raw = 0.4 * spacing_px / med
    k = 10.0 ** np.floor(np.log10(raw))
    return float(max(m * k for m in (1, 2, 5) if m * k <= raw)) if raw >= 1 else 1.0


def undistort_image(image: np.ndarray, K: np.ndarray, dist: np.ndarray, progress=None) -> np.ndarray:
    """``image`` (H, W[, C]) undistorted with the camera model ``K`` (3, 3), ``dist`` (OpenCV
    order), keeping ``K`` as the new camera matrix (so corners stay where the pinhole puts them).
    ``progress``: accepted so that a GUI worker can run it."""
    return cv2.undistort(np.ascontiguousarray(image), np.asarray(K, np.float64), np.asarray(dist, np.float64))


def undistort_points(points: np.ndarray, K: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """Pixel points (N, 2) of the distorted image -> (N, 2) in the image :func:`undistort_image` makes."""
    p = np.asarray(points, np.float64).reshape(-1, 1, 2)
    return cv2.undistortPoints(p, np.asarray(K, np.float64), np.asarray(dist, np.float64), P=np.asarray(K, np.float64)).reshape(-1, 2)
