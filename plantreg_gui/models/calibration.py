"""What the calibration wizard knows about the open session: detections, review choices, results.

Plain state with change events (:mod:`.events`, the models' one mechanism: ``model.<name>.connect``
as the pages did with Qt signals); every computation lives in the calibration engine and runs on
workers (see :mod:`plantreg_gui.gui.calibration.wizard`). Review choices (exclusions, per-image
detection options) are kept in ``Session.review`` and saved with the session, so it reopens
where it was left.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .events import Event

Key = tuple[str, str]  # (pose, camera)


class WizardModel:
    """The wizard's state. Events: ``session_changed()``, ``detection_changed(key)`` (a Key, or
    None for "many changed"), ``review_changed()``, ``calibration_changed()``,
    ``report_changed()``, ``saved_changed()``, ``poses_changed()`` (pose folders added to or
    removed from the session), ``view_selected(key)`` (show this image in the corner review),
    ``board_hint_changed()`` (see :meth:`set_board_hint`), ``review_display_changed()`` (the
    corner review's display choices: :attr:`review_undistorted`).
    ``parent`` is accepted for the wizard's call and not used (the model owns no Qt object)."""

    EVENTS = ("session_changed", "detection_changed", "review_changed", "calibration_changed", "report_changed",
              "saved_changed", "poses_changed", "view_selected", "board_hint_changed",
              "review_display_changed")

    def __init__(self, parent: Any = None) -> None:
        for name in self.EVENTS:
            setattr(self, name, Event(name))
        self.session = None  # core.calibration.Session
        self.detections: dict[Key, Any] = {}
        self.thumbnails: dict[Key, np.ndarray] = {}
        self.calibration = None
        self.report = None
        self.calibration_stale = False
        self.report_stale = False
        self.saved_paths: dict[str, str] = {}
        self.board_hint: tuple[int, int] | None = None  # (columns, rows) found where the session's board was not
        self.review_undistorted = False  # the corner review shows images undistorted with the calibrated model

    # ------------------------------------------------------------------ session
    def set_session(self, session) -> None:
        self.session = session
        self.detections.clear()
        self.thumbnails.clear()
        self.calibration = None
        self.report = None
        self.calibration_stale = self.report_stale = False
        self.saved_paths = {}
        self.board_hint = None
        self.session_changed.emit()
        self.calibration_changed.emit()
        self.report_changed.emit()

    def keys(self) -> list[Key]:
        """Every (pose, camera) of the session, pose-major."""
        s = self.session
        if s is None:
            return []
        return [(p.name, c) for p in s.poses for c in s.camera_names]

    def detections_complete(self) -> bool:
        s = self.session
        if s is None:
            return False
        return all(k in self.detections for k in self.keys())

    # ------------------------------------------------------------------ review (persisted)
    @property
    def excluded(self) -> set[Key]:
        return self.session.excluded() if self.session is not None else set()

    def set_excluded_many(self, keys: set[Key], excluded: bool) -> None:
        ex = self.excluded
        new = (ex | set(keys)) if excluded else (ex - set(keys))
        if new == ex:
            return
        self.session.set_excluded(new)
        self._save_review()
        self.invalidate_calibration()
        self.review_changed.emit()

    def options(self) -> dict[Key, Any]:
        """Detection options per image: the stored ones, with the session-wide detector."""
        from ..core.calibration.detect import DetectOptions

        if self.session is None:
            return {}
        opts = self.session.detect_options()
        if "detector" in self.session.review:  # also for poses added after it was chosen
            det = self.detector()
            for key in self.keys():
                o = opts.get(key, DetectOptions())
                opts[key] = DetectOptions(o.invert, o.enhance, det)
        return opts

    def detector(self) -> str:
        """The session-wide chessboard corner detector (``"auto"`` or ``"classic"``, see
        :class:`~plantreg_gui.core.calibration.detect.DetectOptions`), kept in ``review``."""
        from ..core.calibration.detect import DETECTORS

        det = self.session.review.get("detector", "auto") if self.session is not None else "auto"
        return det if det in DETECTORS else "auto"

    def set_detector(self, detector: str) -> bool:
        """Use ``detector`` for every image: kept in ``review`` and in each image's options (so
        that ``plantreg calibrate`` on the session does the same). False if nothing changed."""
        from ..core.calibration.detect import DetectOptions

        s = self.session
        if s is None or (detector == self.detector() and "detector" in s.review):
            return False
        stored = s.detect_options()
        for key in self.keys():
            o = stored.get(key, DetectOptions())
            new = DetectOptions(o.invert, o.enhance, detector)
            s.set_detect_options(key[0], key[1], None if new == DetectOptions() else new)
        s.review["detector"] = detector
        self._save_review()
        return True

    def set_options(self, key: Key, options) -> None:
        self.session.set_detect_options(key[0], key[1], options)
        self._save_review()

    def set_wizard_page(self, page: int) -> None:
        """Remember the page (in ``review``) so that the session reopens there."""
        if self.session is None:
            return
        if self.session.review.get("wizard_page") != page:
            self.session.review["wizard_page"] = int(page)
            self._save_review()

    def _save_review(self) -> None:
        # a folder without write bits is one the user did not ask to change (the rule of the
        # detection cache): the choices hold for this run only
        if not self.session.writable():
            return
        try:
            self.session.save()
        except OSError:
            pass  # a read-only session still works; the choices just do not persist

    def select_view(self, key: Key) -> None:
        """Ask the corner review to show image ``key`` = (pose, camera)."""
        self.view_selected.emit(tuple(key))

    # ------------------------------------------------------------------ results
    def clear_detections(self) -> None:
        """Forget every detection (before detecting all images again)."""
        self.detections.clear()
        self.thumbnails.clear()
        self.invalidate_calibration()
        self.detection_changed.emit(None)

    def add_pose_folders(self, dirs) -> tuple[list[str], list[str]]:
        """Copy pose folders into the session; returns (added pose names, problems)."""
        from ..core.errors import PlantregError

        added, problems = [], []
        for d in dirs:
            try:
                added.append(self.session.add_pose_from_folder(d).name)
            except (PlantregError, OSError) as e:
                problems.append(str(e))
        if added:
            self.invalidate_calibration()
            self.poses_changed.emit()
        return added, problems

    def remove_poses(self, poses) -> list[str]:
        """Delete pose folders from the session and forget their detections; returns problems."""
        from ..core.errors import PlantregError

        problems = []
        poses = set(poses)
        for p in sorted(poses):
            try:
                self.session.remove_pose(p)
            except (PlantregError, OSError) as e:
                problems.append(str(e))
        for k in [k for k in self.detections if k[0] in poses]:
            self.detections.pop(k, None)
            self.thumbnails.pop(k, None)
        self.invalidate_calibration()
        self.poses_changed.emit()
        self.detection_changed.emit(None)
        return problems

    def set_review_undistorted(self, on: bool) -> None:
        """Show the corner review's images undistorted with the calibrated model (or as taken)."""
        if bool(on) != self.review_undistorted:
            self.review_undistorted = bool(on)
            self.review_display_changed.emit()

    def set_board_hint(self, hint: tuple[int, int] | None) -> None:
        """A chessboard size (columns, rows) found in the images of a camera that found none of
        the session's board (None: no such camera, or no other size found either)."""
        hint = tuple(hint) if hint else None
        if hint != self.board_hint:
            self.board_hint = hint
            self.board_hint_changed.emit()

    def board_hint_text(self) -> str:
        """The hint in words (empty without one)."""
        if self.board_hint is None or self.session is None:
            return ""
        b = self.session.board
        return (f"No {b.columns} x {b.rows} board was found, but a {self.board_hint[0]} x {self.board_hint[1]} one was: "
                "the board size is wrong (count inner corners, where four squares meet).")

    def use_board_hint(self) -> bool:
        """Set the session's board to the hinted size and save the session (the caller detects
        again, e.g. by reopening the session). False without a hint or if it cannot be saved."""
        import dataclasses

        from ..core.errors import PlantregError

        if self.board_hint is None or self.session is None:
            return False
        s = self.session
        old = s.board
        s.board = dataclasses.replace(old, columns=self.board_hint[0], rows=self.board_hint[1])
        if not s.writable():  # (the rule of _save_review) the size holds for this run only
            return True
        try:
            s.save()
        except (PlantregError, OSError):
            s.board = old
            return False
        return True

    def set_saved_paths(self, paths: dict[str, str]) -> None:
        self.saved_paths = dict(paths)
        self.saved_changed.emit()

    def put_detection(self, det, thumb: np.ndarray | None) -> None:
        key = (det.pose, det.camera)
        self.detections[key] = det
        if thumb is not None:
            self.thumbnails[key] = thumb
        self.invalidate_calibration()
        self.detection_changed.emit(key)

    def invalidate_calibration(self) -> None:
        if self.calibration is not None and not self.calibration_stale:
            self.calibration_stale = True
            self.calibration_changed.emit()
        self.invalidate_report()

    def invalidate_report(self) -> None:
        if self.report is not None and not self.report_stale:
            self.report_stale = True
            self.report_changed.emit()

    def set_calibration(self, cal) -> None:
        self.calibration = cal
        self.calibration_stale = False
        self.report = None
        self.report_stale = False
        self.calibration_changed.emit()
        self.report_changed.emit()

    def set_report(self, report) -> None:
        self.report = report
        self.report_stale = False
        self.report_changed.emit()

    def calibration_ready(self) -> bool:
        return self.calibration is not None and not self.calibration_stale

    def report_ready(self) -> bool:
        return self.report is not None and not self.report_stale
