"""Functions the wizard runs on workers (``fn(..., progress=Reporter)``): thin loops around the
calibration engine. No Qt widgets here; detections stream out through a plain callback that the
wizard connects to a Qt signal (queued into the GUI thread)."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Callable

import numpy as np

from ...core.calibration import calibrate, calibrated_rig, error_tables
from ...core.calibration.detect import detect_views, detection_summary
from ...core.jobs.process_job import run_in_process
from ...core.progress import Reporter, ensure_reporter

Key = tuple[str, str]


def detect_job(session, options: dict | None, keys: set[Key] | None, sink: Callable[[Any, Any], None],
               progress: Reporter | None = None) -> int:
    """Detect corners in ``keys`` (all images if None), calling ``sink(detection, thumbnail)`` for
    every result as it arrives. Images are read, detected and thumbnailed in worker processes
    (:func:`~plantreg_gui.core.calibration.detect.detect_views`: one per core, so the GUI
    thread keeps the GIL; detections cached in the session's ``detections.json`` are only
    thumbnailed); one image (a re-detection) goes to the long-lived calculation process, which
    is already running. An unreadable image becomes a failed detection with the reader's
    message instead of ending the run. Returns ``{"detections": n, "board_hint": hint}``: when
    a whole session was detected and a camera's chessboard was found in none of its images,
    ``hint`` is the (columns, rows) that is found in them (the usual mistake: squares counted
    instead of inner corners), else None."""
    progress = ensure_reporter(progress)
    todo = [(p.name, c) for p in session.poses for c in session.camera_names
            if keys is None or (p.name, c) in keys]
    if len(todo) == 1:
        results = run_in_process(_detect_list, session, todo, options, progress=progress)
    else:
        results = detect_views(session, todo, options, progress, thumbnails=THUMB_PX, processes=True,
                               unreadable="fail")
    failed: dict[str, list] = {}
    found: set[str] = set()
    for det, thumb in results:
        sink(det, thumb if det.status != "missing" else None)
        if det.status == "found":
            found.add(det.camera)
        elif det.status == "failed" and det.path is not None:
            failed.setdefault(det.camera, []).append(det.path)
    hint = None
    if keys is None and session.board.type == "chessboard":
        hint = _board_hint(session.board, [paths for cam, paths in failed.items() if cam not in found], progress)
    return {"detections": len(todo), "board_hint": hint}


def _board_hint(board, failed_paths: list[list[Path]], progress: Reporter) -> tuple[int, int] | None:
    """The board size found in a few images of cameras that found no board (see detect_job)."""
    from ...core.calibration import suggest_board_size
    from ...core.errors import InputError
    from ...core.io.imageio import read_image

    for paths in failed_paths:
        progress.check()
        imgs = []
        for path in paths[:3]:
            try:
                imgs.append(read_image(path))
            except InputError:
                pass
        hint = suggest_board_size(imgs, board) if imgs else None
        if hint:
            return tuple(int(v) for v in hint)
    return None


THUMB_PX = 112


def _detect_list(session, todo: list[Key], options: dict | None, progress: Reporter | None = None) -> list:
    """:func:`detect_views` of a few images in this process (the calculation process's side)."""
    return list(detect_views(session, todo, options, progress, thumbnails=THUMB_PX, processes=False,
                             unreadable="fail"))


def calibrate_job(session, detections: dict, excluded: set[Key], progress: Reporter | None = None):
    """The calibration, in the worker process: its bundle adjustment loops in Python and would
    hold the GIL against the GUI thread for seconds (see :mod:`~plantreg_gui.core.jobs.process_job`)."""
    return run_in_process(calibrate, session, detections, excluded, progress=progress)


def tables_job(session, calibration, detections: dict, excluded: set[Key], progress: Reporter | None = None):
    """The error tables, in the worker process (meshing every depth map holds the GIL), with the
    detection figures the report carries (rate per camera, variant per image)."""
    report = run_in_process(error_tables, session, calibration, detections, excluded, progress=progress)
    report.detection = detection_summary(detections)
    return report


def demo_job(folder: Path, progress: Reporter | None = None) -> Path:
    """Write the calibration session of the demo (as ``plantreg demo`` writes it into
    ``calibration/``) into ``folder/calibration`` (replaced) and return that session folder.

    Only the session is rendered: the demo's recording and ground truth (what ``write_demo``
    also writes) belong to the registration workspace and would double the wizard's start-up.
    """
    from ...core.calibration.synthetic import write_calibration_session
    from ...core.synthetic.demo import demo_rig

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    session = folder / "calibration"
    # built beside it under a temporary name and moved into place by the engine
    write_calibration_session(demo_rig("demo"), session, seed=0, progress=ensure_reporter(progress),
                              overwrite=True)
    return session


def save_job(calibration, session, report, excluded: set[Key], rig_path: Path, report_path: Path | None,
             roi_min: np.ndarray, roi_max: np.ndarray, progress: Reporter | None = None) -> dict[str, str]:
    """Write the rig file (ROI and provenance inside) and the report JSON with its CSV tables
    beside it, with the engine's writers (all together, as one transaction)."""
    progress = ensure_reporter(progress)
    progress(0.1, "writing rig file")
    rig = calibrated_rig(calibration, session, report, roi=(np.asarray(roi_min, float), np.asarray(roi_max, float)),
                         excluded=set(excluded))
    rig_path = Path(rig_path)
    from contextlib import ExitStack

    from ...core.calibration.report import report_files
    from ...core.io.lock import claim_output
    from ...core.io.paths import check_output_location

    # the dialogs asked before replacing a file; an input of the session is never replaced. The
    # rig and the report are taken as `plantreg calibrate` takes them (checked, then locked)
    files = [rig_path, *(report_files(report_path) if report is not None and report_path is not None else [])]
    with ExitStack() as claims:
        for i, f in enumerate(files):
            if i <= 1:  # the rig and the report
                claims.enter_context(claim_output(f, "output", overwrite=True, inputs=session.inputs(),
                                                  lock_what="calibration output",
                                                  replace_flag=None))
            else:  # the report's tables follow the report's lock
                check_output_location(f, "output", overwrite=True, inputs=session.inputs(), replace_flag=None)
        return _save(rig, rig_path, calibration, session, report, report_path, progress)


def _save(rig, rig_path: Path, calibration, session, report, report_path: Path | None,
          progress: Reporter) -> dict[str, str]:
    from ...core.calibration.report import write_calibration

    rig_path.parent.mkdir(parents=True, exist_ok=True)
    out: dict[str, str] = {"rig": str(rig_path)}

    if report is not None and report_path is not None:
        progress(0.4, "writing rig file, report and CSV tables")
        Path(report_path).parent.mkdir(parents=True, exist_ok=True)
    # one transaction: all files appear together, or none and the previous set stays
    paths = write_calibration(rig, rig_path, report, report_path)
    if report is not None and report_path is not None:
        out["report"] = str(paths[0])
        out["csv"] = ", ".join(p.name for p in paths[1:-1])
    progress(1.0, "saved")
    return out
