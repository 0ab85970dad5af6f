"""Turning a calibration into files: the rig file with provenance, the report JSON and its CSVs.

Used by ``plantreg calibrate`` and by the wizard's save page, so both write the same thing.
"""

from __future__ import annotations

import datetime as _dt
import json
from pathlib import Path
from typing import Any

import numpy as np

from ... import __version__
from ..errors import InputError
from ..imageio import atomic_write_text
from ..progress import Reporter, ensure_reporter
from ..rig import Rig
from .calibrate import Calibration, calibrate
from .detect import Detection, DetectOptions, detect_session
from .metrics import CalibrationReport, error_tables
from .session import Session, view_key


def calibrated_rig(calibration: Calibration, session: Session, report: CalibrationReport | None = None,
                   roi: tuple[np.ndarray, np.ndarray] | None = None, command: str | None = None,
                   excluded: set[tuple[str, str]] | frozenset = frozenset()) -> Rig:
    """A copy of ``calibration.rig`` with the ROI (if given) and provenance under the extra key
    ``"calibration"``: app and version, session path, UTC date, board, per-camera errors (px and
    normalised), weak and excluded views, and the command line when there is one."""
    src = calibration.rig
    rig = Rig.from_dict(src.to_dict())
    for cam in rig.cameras:  # units and band wavelengths: not calibrated, but the rig file carries them
        cam.extra.update(getattr(session, "camera_meta", {}).get(cam.name, {}))
    if roi is not None:
        lo, hi = np.asarray(roi[0], float), np.asarray(roi[1], float)
        if lo.shape != (3,) or hi.shape != (3,) or not np.all(lo < hi):
            raise InputError("ROI min must be below max in x, y and z")
        rig.roi_min, rig.roi_max = lo, hi
    prov: dict[str, Any] = {
        "app": "plantreg", "version": __version__,
        "date": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        "session": str(Path(session.folder).resolve()),
        "board": calibration.board.to_dict(),
        "excluded": sorted(view_key(p, c) for p, c in excluded),
    }
    prov.update(calibration.provenance())
    if report is not None:
        for name, cell in report.intrinsic.items():
            if cell is not None:
                prov["cameras"][name]["intrinsic_px"] = cell["px"]
                prov["cameras"][name]["intrinsic_normalized"] = cell["normalized"]
        if report.depth_bias_mm:
            prov["tof_bias_mm"] = report.depth_bias_mm
    if command:
        prov["command"] = command
    rig.extra["calibration"] = prov
    return rig


def write_report(report: CalibrationReport, path: str | Path) -> list[Path]:
    """Write the report JSON at ``path`` and its tables as ``<stem>_<table>.csv`` beside it (all
    atomically). Returns the written paths (JSON first)."""
    path = Path(path)
    csvs = report.write_csv(path.parent, prefix=f"{path.stem}_")
    atomic_write_text(path, json.dumps(report.to_dict(), indent=2, default=_json_default) + "\n")
    return [path] + csvs


def _json_default(o: Any) -> Any:
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, (np.floating, np.integer, np.bool_)):
        return o.item()
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")


def run_session(session: Session, excluded: set[tuple[str, str]] | frozenset | None = None,
                options: dict[tuple[str, str], DetectOptions] | None = None,
                roi: tuple[np.ndarray, np.ndarray] | None = None,
                progress: Reporter | None = None) -> tuple[dict[tuple[str, str], Detection], Calibration, CalibrationReport]:
    """Detection, calibration and error tables in one go (what ``plantreg calibrate`` does).
    ``excluded`` defaults to the session's reviewed exclusions."""
    progress = ensure_reporter(progress)
    excluded = session.excluded() if excluded is None else set(excluded)
    if not session.poses:
        raise InputError("the session has no pose folders (one sub-folder per board pose, images named after the cameras)",
                         session.folder)
    detections = {d.key: d for d in detect_session(session, options, progress.sub(0.0, 0.6))}
    cal = calibrate(session, detections, excluded, progress.sub(0.6, 0.75))
    report = error_tables(session, cal, detections, excluded, progress.sub(0.75, 1.0), roi=roi)
    return detections, cal, report
