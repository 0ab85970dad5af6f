"""Rig calibration: boards, capture sessions, corner detection, intrinsics, joint extrinsics and
the paper's three error tables (intrinsic, extrinsic/epipolar, depth).

Typical use (what ``plantreg calibrate`` does)::

    session = Session.load(folder)
    detections = {d.key: d for d in detect_session(session)}          # generator: one per image
    cal = calibrate(session, detections, session.excluded())
    report = error_tables(session, cal, detections, session.excluded())
    calibrated_rig(cal, session, report).save("rig.json"); write_report(report, "report.json")

:func:`detect_image` returns a :class:`Detection` whose ``pose``/``camera`` are empty.
"""

from .board import Board
from .calibrate import Calibration, CameraCalibration, calibrate, usable_views
from .detect import (FAILED, FOUND, MISSING, Detection, DetectOptions, detect_image, detect_session,
                     detect_view, suggest_board_size, to_gray)
from .metrics import CalibrationReport, epipolar_distances, error_tables
from .report import calibrated_rig, run_session, write_report
from .session import Pose, Session, parse_view_key, view_key
from .synthetic import read_truth, write_calibration_session

__all__ = [
    "Board", "Pose", "Session", "view_key", "parse_view_key",
    "DetectOptions", "Detection", "detect_image", "detect_session", "detect_view", "suggest_board_size", "to_gray",
    "FOUND", "FAILED", "MISSING",
    "calibrate", "Calibration", "CameraCalibration", "usable_views",
    "error_tables", "CalibrationReport", "epipolar_distances",
    "calibrated_rig", "write_report", "run_session",
    "write_calibration_session", "read_truth",
]
