"""The landmark page's model: a rig, its recordings and a landmarks file being edited (Qt-free).

Everything the desktop app's landmark page shows and does lives here, so a test (or another
front end) drives it without Qt: pick a recording and a camera, click a depth-camera pixel then
the same point in the camera (:meth:`LandmarkSession.click_depth`, :meth:`click_camera`), move or
delete points, undo/redo, fit the rig (core/rigfit/rigfit.py), nudge a camera's pose in its own frame
(like OpenCalib's manual panel), refine from the images (core/rigfit/refine.py), save.

Change notification is napari-style: ``session.events.<name>.connect(callback)``; callbacks get
no arguments and read the session. Events: ``points`` (landmarks edited, or their depths
changed meaning: snapping switched), ``rig`` (the rig changed: fit, nudge, refine, undo),
``selection`` (recording, camera, selected point or pending click), ``report`` (a new
fit/refine report), ``options`` (a setting the fit uses: :attr:`LandmarkSession.snap_depth`).

Each landmark's depth is checked as the fit checks it (:func:`~..core.rigfit.rigfit.check_landmark_depth`:
on the surface under the click, snapped onto a nearer surface beside it, or left out) and shown
in the table (:meth:`LandmarkSession.depth_checks`).

Long work (fit, refine, the overlay's registration) is split into a pure *job* computed on
copies (safe on a worker thread) and an ``apply_*`` that updates the session on the caller's
thread -- napari's snapshot / compute / apply.

Length: the landmark page's whole model (pairs, fits, leave-one-out, nudges, refinement) in one
Qt-free class with its events; the computations it calls live in :mod:`plantreg_gui.core.rigfit`.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import cv2
import numpy as np

from ..core.errors import InputError, show_path
from ..core.data.landmarks import Landmark, LandmarkSet
from ..core.progress import Reporter, ensure_reporter
from ..core.data.recording import Recording
from ..core.camera.rig import Rig
from ..core.rigfit.rigfit import (
    DepthCheck, FitResult, RecordingLandmarks, check_landmark_depth, evaluate_landmarks, fit_rig,
)
from .events import Events


class LandmarkEvents(Events):
    NAMES = ("points", "rig", "selection", "report", "options")


@dataclass
class OverlayImages:
    """The chosen camera registered into the depth camera's grid, for the overlay: ``base`` and
    ``registered`` (H, W, 3) uint8 RGB of one shape; ``mapped`` (H, W) bool where a value arrived."""

    recording: str
    camera: str
    base: np.ndarray
    registered: np.ndarray
    mapped: np.ndarray


def _rotation(axis: int, deg: float) -> np.ndarray:
    v = np.zeros(3)
    v[axis] = math.radians(deg)
    return cv2.Rodrigues(v)[0]


class LandmarkSession:
    """State of the landmark page. ``rig`` is replaced (never mutated in place) on fit, nudge,
    refine and undo, so a worker can hold the previous one safely."""

    def __init__(self, rig: Rig, landmarks: LandmarkSet | None = None,
                 recordings: dict[str, Recording] | None = None) -> None:
        self.events = LandmarkEvents()
        self.rig = rig
        self.landmarks = landmarks if landmarks is not None else LandmarkSet(base=Path.cwd())
        self._recordings: dict[str, Recording] = dict(recordings or {})
        self._depth_m: dict[str, np.ndarray] = {}
        keys = list(self.landmarks.recordings) + [k for k in self._recordings if k not in self.landmarks.recordings]
        for k in keys:
            self.landmarks.recordings.setdefault(k, [])
        self.recording_key: str | None = keys[0] if keys else None
        others = self.camera_names()
        used = [c for c in self.landmarks.camera_names if c in others]
        self.camera: str | None = used[0] if used else (others[0] if others else None)
        self.selected: int | None = None
        self.pending: np.ndarray | None = None   # a depth pixel waiting for its camera pixel
        self.report: dict[str, Any] | None = None
        self.warnings: list[str] = []
        self.free: frozenset[str] = frozenset()
        #: a landmark whose depth lies behind the surface beside it is put onto that surface
        #: (True, as fit-rig) or left out of the fit (False, as fit-rig --no-snap-depth)
        self.snap_depth = True
        #: (recording, u, v, ground_z) -> DepthCheck (snapping on): a repaint, a fit or switching
        #: snapping reads a landmark's depth once
        self._depth_checks: dict[tuple, DepthCheck] = {}
        self._undo: list[tuple[dict, dict]] = []
        self._redo: list[tuple[dict, dict]] = []
        self.modified = False
        #: the rig (cameras) the report describes: a nudge or an undo makes the report stale
        self._report_cameras: list[dict] | None = None
        #: what was last opened or saved, to tell the user what closing would lose
        self._saved_points = self._nonempty_points()
        self._saved_cameras = self._cameras_dicts()
        #: the refinement routine (core.refine.refine_rig unless replaced, e.g. by a test)
        self.refine_fn: Callable[..., Any] | None = None

    # ------------------------------------------------------------------ opening
    @classmethod
    def open(cls, rig_path: str | Path, landmarks_path: str | Path | None = None) -> "LandmarkSession":
        """A session on files: the rig and (optionally) a landmarks file, checked against each other."""
        rig = Rig.load(rig_path)
        if landmarks_path is not None and Path(landmarks_path).exists():
            lms = LandmarkSet.load(landmarks_path)
            lms.check(rig)
        else:
            lms = LandmarkSet(base=Path(landmarks_path).parent if landmarks_path else Path.cwd(),
                              path=Path(landmarks_path) if landmarks_path else None)
        return cls(rig, lms)

    @classmethod
    def load(cls, rig_path: str | Path, landmarks_path: str | Path | None = None,
             recordings: list[str | Path] | None = None, progress: Reporter | None = None) -> "LandmarkSession":
        """:meth:`open` plus ``recordings`` (folders to add), with every recording of the session
        read now (images and depth map): a routine for a worker, so that the page's first paint,
        residuals, fit and refinement read nothing from disk. Cancellable between recordings.
        Raises :class:`InputError` naming a bad file, or when there is no recording at all."""
        progress = ensure_reporter(progress)
        progress(0.0, "reading the rig and the landmarks")
        s = cls.open(rig_path, landmarks_path)
        for r in recordings or []:
            progress.check()
            s.add_recording(r)
        if s.recording_key is None:
            raise InputError("no recording: the landmarks file names none; give --recording DIR", landmarks_path)
        keys = [s.recording_key] + [k for k in s.recording_keys if k != s.recording_key]  # the shown one first
        for i, k in enumerate(keys):
            progress(0.05 + 0.95 * i / len(keys), f"reading recording {i + 1}/{len(keys)}: {Path(k).name}")
            s.depth_m(k)  # reads the recording too (a bad one is reported here, not on first paint)
            s.depth_checks(k)  # the table's depth flags, read here rather than on the first paint
        progress(1.0, "recordings read")
        return s

    def add_recording(self, folder: str | Path) -> str:
        """Add a recording folder (key relative to the landmarks file where possible); returns its key."""
        folder = Path(folder).resolve()
        rec = Recording.load(folder, self.rig)
        base = self.landmarks.base.resolve() if self.landmarks.base else None
        try:
            key = str(folder.relative_to(base)) if base else str(folder)
        except ValueError:
            key = str(folder)
        self._recordings[key] = rec
        self.landmarks.recordings.setdefault(key, [])
        self.set_recording(key)
        return key

    # ------------------------------------------------------------------ data access
    @property
    def recording_keys(self) -> list[str]:
        return list(self.landmarks.recordings)

    def camera_names(self) -> list[str]:
        """The rig's cameras other than the depth camera (the ones landmarks are clicked in)."""
        d = self.rig.depth().name
        return [c.name for c in self.rig.cameras if c.name != d]

    def recording(self, key: str | None = None) -> Recording:
        key = key or self.recording_key
        if key is None:
            raise InputError("no recording is open")
        if key not in self._recordings:
            folder = self.landmarks.folder(key)
            try:
                rec = Recording.load(folder)
                rec.check(self.rig, need_depth=True)
            except InputError as e:  # a recording the landmarks file names: say which file names it
                if self.landmarks.path is None:
                    raise
                where = show_path(e.path) if e.path is not None else show_path(folder)
                raise InputError(f"recording '{key}' it names: {e.detail} ({where})", self.landmarks.path) from None
            self._recordings[key] = rec
        return self._recordings[key]

    def depth_m(self, key: str | None = None) -> np.ndarray:
        """(H, W) metres, NaN = none, of recording ``key`` (default the current one)."""
        key = key or self.recording_key
        if key not in self._depth_m:
            self._depth_m[key] = self.recording(key).depth_m(self.rig.depth_scale)
        return self._depth_m[key]

    def depth_image(self, key: str | None = None) -> np.ndarray:
        """The image shown on the left: the depth camera's own image (e.g. infrared) if the
        recording has one, else the depth map."""
        rec = self.recording(key)
        d = self.rig.depth().name
        return rec.images[d] if d in rec.images else self.depth_m(key)

    def camera_image(self, camera: str | None = None, key: str | None = None) -> np.ndarray:
        camera = camera or self.camera
        rec = self.recording(key)
        if camera not in rec.images:
            raise InputError(f"recording '{key or self.recording_key}' has no image of camera '{camera}'")
        return rec.images[camera]

    @property
    def points(self) -> list[Landmark]:
        """The current recording's landmarks (edit them through the session's methods)."""
        return self.landmarks.recordings.get(self.recording_key, []) if self.recording_key else []

    # ------------------------------------------------------------------ selection
    def set_recording(self, key: str) -> None:
        if key not in self.landmarks.recordings:
            raise InputError(f"no recording '{key}' in this session")
        self.recording_key, self.selected, self.pending = key, None, None
        self.events.selection.emit()

    def set_camera(self, camera: str) -> None:
        if camera not in self.camera_names():
            raise InputError(f"camera '{camera}' is not one of {', '.join(self.camera_names())}")
        self.camera, self.pending = camera, None
        self.events.selection.emit()

    def select(self, index: int | None) -> None:
        self.selected = index if index is None or 0 <= index < len(self.points) else None
        self.events.selection.emit()

    # ------------------------------------------------------------------ undo
    def _points_dicts(self) -> dict[str, list[dict]]:
        return copy.deepcopy({k: [lm.to_dict() for lm in v] for k, v in self.landmarks.recordings.items()})

    def _nonempty_points(self) -> dict[str, list[dict]]:
        return {k: v for k, v in self._points_dicts().items() if v}  # a recording just added is no edit

    def _cameras_dicts(self) -> list[dict]:
        return [c.to_dict() for c in self.rig.cameras]

    def _snapshot(self) -> tuple:
        # the report travels with the rig it describes: undoing a fit also undoes its report
        return (self._points_dicts(), self.rig.to_dict(), copy.deepcopy(self.report), list(self.warnings),
                self._report_cameras)

    def _restore(self, snap: tuple) -> None:
        pts, rig, self.report, self.warnings, self._report_cameras = snap
        self.landmarks.recordings = {k: [Landmark(d["depth_uv"], d.get("cameras", {}), d.get("note", ""),
                                                  {x: y for x, y in d.items()
                                                   if x not in ("depth_uv", "cameras", "note")})
                                         for d in v] for k, v in pts.items()}
        self.rig = Rig.from_dict(rig)
        self.selected, self.pending = None, None

    @property
    def report_is_current(self) -> bool:
        """True when :attr:`report` describes the current rig (not one changed since by a nudge)."""
        return self.report is not None and self._report_cameras == self._cameras_dicts()

    def unsaved(self) -> list[str]:
        """What closing would lose: 'landmarks' and/or 'rig' when changed since opened or saved."""
        out = []
        if self._nonempty_points() != self._saved_points:
            out.append("landmarks")
        if self._cameras_dicts() != self._saved_cameras:
            out.append("rig")
        return out

    def _push(self) -> None:
        self._undo.append(self._snapshot())
        self._redo.clear()
        self.modified = True

    def can_undo(self) -> bool:
        return bool(self._undo)

    def can_redo(self) -> bool:
        return bool(self._redo)

    def undo(self) -> None:
        if self._undo:
            self._redo.append(self._snapshot())
            self._restore(self._undo.pop())
            self._emit_all()

    def redo(self) -> None:
        if self._redo:
            self._undo.append(self._snapshot())
            self._restore(self._redo.pop())
            self._emit_all()

    def _emit_all(self) -> None:
        self.events.points.emit()
        self.events.rig.emit()
        self.events.selection.emit()
        self.events.report.emit()

    # ------------------------------------------------------------------ editing points
    def click_depth(self, uv: Any) -> None:
        """A click in the depth camera's view: the first half of a new landmark."""
        self.pending = np.asarray(uv, float).reshape(2)
        self.selected = None
        self.events.selection.emit()

    def cancel_pending(self) -> None:
        self.pending = None
        self.events.selection.emit()

    def click_camera(self, uv: Any) -> int | None:
        """A click in the camera's view. Completes the pending landmark; without one, gives the
        selected landmark its pixel in this camera (if it has none yet). Returns the point's
        index or None when the click did nothing."""
        uv = np.asarray(uv, float).reshape(2)
        if self.pending is not None:
            self._push()
            self.points.append(Landmark(self.pending, {self.camera: uv}))
            self.pending = None
            self.selected = len(self.points) - 1
        elif self.selected is not None and self.camera not in self.points[self.selected].cameras:
            self._push()
            self.points[self.selected].cameras[self.camera] = uv
        else:
            return None
        self.events.points.emit()
        self.events.selection.emit()
        return self.selected

    def add_point(self, depth_uv: Any, cameras: dict[str, Any], note: str = "") -> int:
        self._push()
        self.points.append(Landmark(depth_uv, cameras, note))
        self.selected = len(self.points) - 1
        self.events.points.emit()
        return self.selected

    def move_point(self, index: int, where: str, uv: Any, *, undoable: bool = True) -> None:
        """Move point ``index``'s pixel in ``where`` ('depth' or a camera name) to ``uv`` (2,).
        A drag calls this with ``undoable=False`` while moving and once with True at the start."""
        if undoable:
            self._push()
        lm = self.points[index]
        uv = np.asarray(uv, float).reshape(2)
        if where == "depth":
            lm.depth_uv = uv
        else:
            lm.cameras[where] = uv
        self.modified = True
        self.events.points.emit()

    def delete_point(self, index: int | None = None) -> None:
        """Delete point ``index`` (default the selected one) from the current recording."""
        index = self.selected if index is None else index
        if index is None or not 0 <= index < len(self.points):
            return
        self._push()
        del self.points[index]
        self.selected = None
        self.events.points.emit()
        self.events.selection.emit()

    # ------------------------------------------------------------------ depth under the landmarks
    def set_snap_depth(self, on: bool) -> None:
        """Snap a landmark whose depth lies behind the surface beside it onto that surface (True,
        the default, as ``fit-rig``) or leave it out of the fit (False, ``--no-snap-depth``)."""
        on = bool(on)
        if on != self.snap_depth:
            self.snap_depth = on
            self.events.options.emit()
            self.events.points.emit()  # depth flags and residuals changed

    def depth_check(self, index: int, key: str | None = None) -> DepthCheck:
        """How the fit takes point ``index`` of recording ``key`` (default the current one)'s depth."""
        key = key or self.recording_key
        lm = self.landmarks.recordings[key][index]
        u, v = (float(a) for a in lm.depth_uv)
        ck = (key, u, v, self.rig.ground_z)
        if ck not in self._depth_checks:
            if len(self._depth_checks) > 4096:
                self._depth_checks.clear()
            self._depth_checks[ck] = check_landmark_depth(self.depth_m(key), lm.depth_uv, self.rig.ground_z)
        return self._depth_checks[ck].snapping(self.snap_depth)

    def depth_checks(self, key: str | None = None) -> dict[int, DepthCheck]:
        """:meth:`depth_check` of every point of recording ``key`` (default the current one)."""
        key = key or self.recording_key
        return {i: self.depth_check(i, key) for i in range(len(self.landmarks.recordings.get(key, [])))}

    # ------------------------------------------------------------------ residuals
    def _recording_landmarks(self, keys: list[str] | None = None) -> list[RecordingLandmarks]:
        keys = keys if keys is not None else [k for k, v in self.landmarks.recordings.items() if v]
        return [RecordingLandmarks(k, self.depth_m(k), self.landmarks.recordings[k], snap_depth=self.snap_depth,
                                   depth_checks=self.depth_checks(k)) for k in keys]

    def residuals(self, camera: str | None = None) -> dict[int, float]:
        """Residual (px, predicted minus clicked) of the current rig for each point of the current
        recording that has a pixel in ``camera`` (default the chosen one) and a depth."""
        camera = camera or self.camera
        if not self.points or camera is None:
            return {}
        rows, _rej = evaluate_landmarks(self.rig, self._recording_landmarks([self.recording_key]), [camera])
        return {d["index"]: d["residual_px"] for d in rows}

    def set_aside(self) -> set[tuple[str, int, str]]:
        """(recording, index, camera) of the landmarks the fit behind the current rig left out as
        outliers: from this page's fit, else from the rig's calibration record (a rig fitted by
        ``fit-rig``). A row counts only while its point still carries the note it was fitted with
        (an edited point is no longer the one the fit set aside)."""
        rep = self.report if self.report is not None else self.rig.extra.get("calibration")
        rows = rep.get("residuals") if isinstance(rep, dict) else None
        out: set[tuple[str, int, str]] = set()
        for d in rows if isinstance(rows, list) else []:
            if not (isinstance(d, dict) and d.get("outlier")):
                continue
            pts = self.landmarks.recordings.get(d.get("recording"))
            i = d.get("index")
            if pts and isinstance(i, int) and 0 <= i < len(pts) and pts[i].note == d.get("note", pts[i].note):
                out.add((d["recording"], i, d.get("camera")))
        return out

    def summary(self) -> dict[str, dict[str, Any]]:
        """Per camera over every recording: ``n``, ``median_px``, ``p90_px``, ``max_px`` of the
        current rig, over the landmarks the fit used (as ``fit-rig`` reports them); ``set_aside``:
        how many of the camera's landmarks the fit left out as outliers (:meth:`set_aside`)."""
        from ..core.rigfit.rigfit import _stats_by

        rows, _ = evaluate_landmarks(self.rig, self._recording_landmarks())
        aside = self.set_aside()
        for d in rows:
            d["outlier"] = (d["recording"], d["index"], d["camera"]) in aside
        out = _stats_by(rows, ("camera",)) if rows else {}
        for c, v in out.items():
            v["set_aside"] = sum(1 for d in rows if d["camera"] == c and d["outlier"])
        return out

    def predicted(self, index: int, camera: str | None = None) -> np.ndarray | None:
        """Where the current rig puts point ``index``'s depth pixel in ``camera`` (2,), or None."""
        camera = camera or self.camera
        lm = self.points[index]
        z = self.depth_check(index).z_m  # the depth the fit uses (snapped, or none when left out)
        if not np.isfinite(z):
            return None
        dcam = self.rig.depth()
        xy = dcam.undistort_normalized(lm.depth_uv[None])
        X = dcam.to_rig(np.array([[xy[0, 0] * z, xy[0, 1] * z, z]]))
        uv, zc = self.rig.camera(camera).project(X)
        return uv[0] if zc[0] > 0 else None

    def table(self) -> list[dict[str, Any]]:
        """Rows for the points table of the current recording, worst first (no residual last):
        ``index``, ``depth_uv``, ``camera_uv`` (or None), ``residual_px`` (or None), ``note``,
        ``depth`` (:class:`DepthCheck`: how the fit takes the point's depth)."""
        res = self.residuals()
        checks = self.depth_checks()
        rows = [{"index": i, "depth_uv": lm.depth_uv, "camera_uv": lm.cameras.get(self.camera),
                 "residual_px": res.get(i), "note": lm.note, "depth": checks[i]} for i, lm in enumerate(self.points)]
        rows.sort(key=lambda d: (d["residual_px"] is None, -(d["residual_px"] or 0.0)))
        return rows

    # ------------------------------------------------------------------ fit
    def fit_job(self, free: frozenset[str] | None = None) -> Callable[..., FitResult]:
        """A routine ``(progress=Reporter) -> FitResult`` on copies of the current state."""
        rig = Rig.from_dict(self.rig.to_dict())
        recs = [RecordingLandmarks(r.name, r.depth_m, [copy.deepcopy(lm) for lm in r.points], r.snap_depth,
                                   r.depth_checks) for r in self._recording_landmarks()]
        free = self.free if free is None else free

        def job(progress: Reporter | None = None) -> FitResult:
            if progress is not None:
                progress(0.0, "fitting the rig to the landmarks")
            # leave-one-recording-out when there are two recordings (the report's LOO median); not the
            # per-landmark refits of a single recording, which would hold the page's fit up
            return fit_rig(rig, recs, free=free, loo=len(recs) >= 2)

        return job

    def apply_fit(self, result: Any) -> None:
        """Take a fit's (or refinement's) rig, report and warnings (undoable)."""
        self._push()
        self.rig = result.rig
        self.report = result.report
        self.warnings = list(result.warnings)
        self._report_cameras = self._cameras_dicts()
        self.events.rig.emit()
        self.events.points.emit()  # residuals changed
        self.events.report.emit()

    def fit(self, free: frozenset[str] | None = None) -> FitResult:
        """Fit now, on this thread (tests, scripts)."""
        res = self.fit_job(free)()
        self.apply_fit(res)
        return res

    # ------------------------------------------------------------------ nudge
    def nudge(self, kind: str, axis: int, amount: float, camera: str | None = None) -> None:
        """Move ``camera`` (default the chosen one) in its own frame, undoably.

        ``kind='rotate'``: rotate by ``amount`` degrees about the camera's x (0), y (1) or z (2)
        axis through its optical centre (the centre stays put). ``kind='translate'``: move the
        optical centre by ``amount`` metres along the camera's axis ``axis``.
        With X_cam = R @ X_rig + t: rotation R' = dR @ R, t' = dR @ t; translation t' = t - d.
        """
        camera = camera or self.camera
        if camera == self.rig.depth().name:
            raise InputError("the depth camera's pose defines the rig frame: nudge another camera")
        self._push()
        rig = Rig.from_dict(self.rig.to_dict())
        cam = rig.camera(camera)
        if kind == "rotate":
            dR = _rotation(axis, amount)
            cam.R_cam_rig, cam.t_cam_rig = dR @ cam.R_cam_rig, dR @ cam.t_cam_rig
        elif kind == "translate":
            d = np.zeros(3)
            d[axis] = amount
            cam.t_cam_rig = cam.t_cam_rig - d
        else:
            raise ValueError(f"nudge kind must be 'rotate' or 'translate', got {kind!r}")
        self.rig = rig
        self.events.rig.emit()
        self.events.points.emit()
        self.events.report.emit()  # a fit's report no longer describes this rig

    # ------------------------------------------------------------------ refine
    def refine_job(self, cameras: list[str] | None = None, *, in_process: bool = False,
                   **kw: Any) -> Callable[..., Any]:
        """A routine ``(progress=Reporter) -> RefineResult`` (core/rigfit/refine.py) on copies, over
        every recording of the session, checked against the landmarks.

        ``in_process``: run the refinement in a child process (:func:`~.process_job.call_in_process`;
        the routine must be picklable). For the desktop app: on threads, the refinement's camera
        threads hold the GIL for stretches (GUI-thread gaps while it runs) and notice a cancel only
        at their next cancellation point (seconds apart on the real plants); a child is stopped at once."""
        fn = self.refine_fn
        if fn is None:
            try:
                from ..core.rigfit.refine import refine_rig as fn
            except ImportError:
                raise InputError("automatic refinement is not available in this plantreg (no core.refine)") from None
        rig = Rig.from_dict(self.rig.to_dict())
        keys = list(self.landmarks.recordings)
        recs = [self.recording(k) for k in keys]
        lms = copy.deepcopy(self.landmarks)
        free = frozenset(it for it in self.free if it.endswith("focal"))

        def job(progress: Reporter | None = None) -> Any:
            if in_process:
                from ..core.jobs.process_job import call_in_process

                return call_in_process(fn, rig, recs, cameras=cameras, free=free, landmarks=lms,
                                       progress=progress, **kw)
            return fn(rig, recs, cameras=cameras, free=free, landmarks=lms, progress=progress, **kw)

        return job

    # ------------------------------------------------------------------ overlay
    def overlay_job(self) -> Callable[..., OverlayImages]:
        """A routine ``(progress=Reporter) -> OverlayImages``: the chosen camera registered into
        the depth camera's pixel grid by the current rig (core/registration/register.py), both as RGB8."""
        from ..core.display.display import to_rgb8
        from ..core.registration.register import Registrar

        rig = Rig.from_dict(self.rig.to_dict())
        key, camera = self.recording_key, self.camera
        rec = self.recording()
        dname = rig.depth().name
        dmod, cmod = rig.depth().modality, rig.camera(camera).modality
        base_img = self.depth_image()

        def job(progress: Reporter | None = None) -> OverlayImages:
            res = Registrar(rig, rec).register(dname, progress)
            reg = np.asarray(res.registered[camera])
            mapped = np.isfinite(reg if reg.ndim == 2 else reg[..., 0])
            return OverlayImages(key, camera, to_rgb8(np.asarray(base_img), dmod),
                                 to_rgb8(reg, cmod, mask=mapped), mapped)

        return job

    # ------------------------------------------------------------------ saving
    def save_landmarks(self, path: str | Path | None = None) -> Path:
        """Write the landmarks file (atomically). Recording keys stay relative to the file's folder
        when it is saved where it was read; saving elsewhere rewrites them against the new folder."""
        path = Path(path or self.landmarks.path or "")
        if not path.name:
            raise InputError("no landmarks file name given")
        out = copy.copy(self.landmarks)
        if out.base is not None and path.parent.resolve() != out.base.resolve():
            import os

            out = copy.copy(self.landmarks)
            out.recordings = {os.path.relpath(self.landmarks.folder(k).resolve(), path.parent.resolve()): v
                              for k, v in self.landmarks.recordings.items()}
        out.save(path)
        self.modified = False
        self._saved_points = self._nonempty_points()
        return path

    def save_rig(self, path: str | Path) -> Path:
        """Write the current rig, with the last fit/refine report as its ``"calibration"`` provenance."""
        from ..core.camera.record import landmark_record

        rig = Rig.from_dict(self.rig.to_dict())
        if self.report is not None and not self.report_is_current or \
                self.report is None and self._cameras_dicts() != self._saved_cameras:
            # moved by hand since the last fit (or since opened): the old provenance and its
            # residuals would describe another rig -- say what this one is, keep the old as history
            before = self.report if self.report is not None else rig.extra.get("calibration")
            landmark_record(
                "manual nudge", "plantreg-gui landmark page", {"per_camera": self.summary()},
                landmarks_file=str(self.landmarks.path.resolve()) if self.landmarks.path else None,
                note="camera poses moved by hand after the fit below; per_camera are this rig's residuals",
                before_nudge={k: v for k, v in (before or {}).items() if k != "time_s"},
                warnings=self.warnings if self.report is not None else [],
            ).store(rig)
        elif self.report is not None:
            landmark_record(
                self.report.get("method", "landmarks"), "plantreg-gui landmark page", self.report,
                landmarks_file=str(self.landmarks.path.resolve()) if self.landmarks.path else None,
                warnings=self.warnings,
            ).store(rig)
        rig.save(path)
        self._saved_cameras = self._cameras_dicts()
        return Path(path)
