"""Functions the wizard runs on workers (``fn(..., progress=Reporter)``): thin loops around the
calibration engine. No Qt widgets here; detections stream out through a plain callback that the
wizard connects to a Qt signal (queued into the GUI thread)."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Callable

import numpy as np

from ...core.calibration import Detection, calibrate, calibrated_rig, detect_session, error_tables
from ...core.imageio import read_image
from ...core.progress import Reporter, ensure_reporter
from .widgets import thumbnail

Key = tuple[str, str]


def detect_job(session, options: dict | None, keys: set[Key] | None, sink: Callable[[Any, Any], None],
               progress: Reporter | None = None) -> int:
    """Detect corners in ``keys`` (all images if None), calling ``sink(detection, thumbnail)`` for
    every result as it arrives. An unreadable image becomes a failed detection with the reader's
    message instead of ending the run. Returns the number of detections."""
    from ...core.errors import InputError

    progress = ensure_reporter(progress)
    todo = [(p.name, c) for p in session.poses for c in session.camera_names
            if keys is None or (p.name, c) in keys]
    poses = {p.name: p for p in session.poses}
    done: set[Key] = set()
    n_total = max(1, len(todo))
    while len(done) < len(todo):
        rest = [k for k in todo if k not in done]
        sub = progress.sub(len(done) / n_total, 1.0)
        try:
            for det in detect_session(session, options or None, progress=sub, views=rest):
                key = (det.pose, det.camera)
                done.add(key)
                sink(det, _thumb(poses[det.pose].images.get(det.camera)) if det.status != "missing" else None)
        except InputError as e:  # the view being read is unreadable: say so, go on with the others
            key = next(k for k in todo if k not in done)
            done.add(key)
            sink(Detection(key[0], key[1], "failed", f"unreadable image: {e}", None, None, (0, 0), False,
                           poses[key[0]].images.get(key[1])), None)
    return len(done)


def _thumb(path) -> np.ndarray | None:
    if path is None:
        return None
    try:
        return thumbnail(read_image(path), 112)
    except Exception:  # the detection already carries the reason a file is bad
        return None


def calibrate_job(session, detections: dict, excluded: set[Key], progress: Reporter | None = None):
    return calibrate(session, detections, excluded, progress=progress)


def tables_job(session, calibration, detections: dict, excluded: set[Key], progress: Reporter | None = None):
    return error_tables(session, calibration, detections, excluded, progress=progress)


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
    rig_path.parent.mkdir(parents=True, exist_ok=True)
    out: dict[str, str] = {"rig": str(rig_path)}
    from ...core.calibration.report import write_calibration

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
