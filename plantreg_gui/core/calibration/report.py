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
from ..io.imageio import atomic_files
from ..progress import Reporter, ensure_reporter
from ..camera.rig import Rig
from .calibrate import Calibration, calibrate
from .detect import Detection, DetectOptions, detect_session, detection_summary
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
        meta = getattr(session, "camera_meta", {}).get(cam.name, {})
        cam.extra.update({k: v for k, v in meta.items() if k in ("units", "bands")})
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


#: Every table a report can have as CSV (``<report stem>_<table>.csv``): the names a
#: command must keep free and the stale ones a rewrite removes.
CSV_TABLES = ("intrinsic", "uncertainty", "extrinsic_px", "extrinsic_normalized", "depth_px", "depth_normalized", "depth_bias")


def report_files(report_path: str | Path) -> list[Path]:
    """The report JSON and every CSV that can go beside it."""
    p = Path(report_path)
    return [p] + [p.parent / f"{p.stem}_{t}.csv" for t in CSV_TABLES]


def write_report(report: CalibrationReport, path: str | Path) -> list[Path]:
    """Write the report JSON at ``path`` and its tables as ``<stem>_<table>.csv`` beside it, as
    one transaction (:func:`write_calibration`). Returns the written paths (JSON first)."""
    return write_calibration(None, None, report, path)


def write_calibration(rig: Rig | None, rig_path: str | Path | None, report: CalibrationReport | None = None,
                      report_path: str | Path | None = None) -> list[Path]:
    """Write the rig file, the report JSON and its CSV tables as ONE transaction
    (:func:`~plantreg_gui.core.io.imageio.atomic_files`): all of them appear together, or none and
    the previous set stays as it was (a full disk, a permission error, Ctrl-C or SIGTERM never
    leave a report without its rig, or destroy the previous report). CSVs of a previous report
    that the new one does not have are removed with it. Returns the written paths (report JSON,
    CSVs, then the rig)."""
    texts: dict[Path, str] = {}
    stale: list[Path] = []
    if report is not None and report_path is not None:
        rp = Path(report_path)
        d = report.to_dict()
        if getattr(report, "detection", None):  # detection figures (detect.detection_summary), when known
            d["detection"] = report.detection
        texts[rp] = json.dumps(d, indent=2, default=_json_default) + "\n"
        for name, text in report.csv_tables().items():
            texts[rp.parent / f"{rp.stem}_{name}.csv"] = text
        stale = [p for p in report_files(rp)[1:] if p not in texts]
    if rig is not None and rig_path is not None:
        texts[Path(rig_path)] = json.dumps(rig.to_dict(), indent=2) + "\n"
    from ..io.lock import output_lock

    # the one output lock (the wizard's save too; re-entrant under plantreg calibrate's own)
    locked = [p for p in (rig_path, report_path) if p is not None]
    with output_lock(*locked, what="calibration output"), atomic_files(list(texts), remove=stale) as tmps:
        for final, text in texts.items():
            try:
                tmps[final].write_text(text, encoding="utf-8")
            except OSError as e:  # write() errors carry no file name: give it the one being written
                raise OSError(e.errno, e.strerror or str(e), str(tmps[final])) from None
    return list(texts)


def _json_default(o: Any) -> Any:
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, (np.floating, np.integer, np.bool_)):
        return o.item()
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")


def run_session(session: Session, excluded: set[tuple[str, str]] | frozenset | None = None,
                options: dict[tuple[str, str], DetectOptions] | None = None,
                roi: tuple[np.ndarray, np.ndarray] | None = None,
                progress: Reporter | None = None, known: dict | None = None,
                ) -> tuple[dict[tuple[str, str], Detection], Calibration, CalibrationReport]:
    """Detection, calibration and error tables in one go (what ``plantreg calibrate`` does).
    ``excluded`` defaults to the session's reviewed exclusions; ``known`` camera ->
    :class:`~.calibrate.KnownIntrinsics` (default: the session's ``"intrinsics"`` entries)."""
    progress = ensure_reporter(progress)
    excluded = session.excluded() if excluded is None else set(excluded)
    if not session.poses:
        raise InputError("the session has no pose folders (one sub-folder per board pose, images named after the cameras)",
                         session.folder)
    detections = {d.key: d for d in detect_session(session, options, progress.sub(0.0, 0.6))}
    cal = calibrate(session, detections, excluded, progress.sub(0.6, 0.75), known=known)
    report = error_tables(session, cal, detections, excluded, progress.sub(0.75, 1.0), roi=roi)
    report.detection = detection_summary(detections)
    return detections, cal, report
