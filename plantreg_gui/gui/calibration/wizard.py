"""The calibration wizard: a guided flow over seven pages, every computation on a worker.

Pages: 1 rig and board, 2 capture list, 3 corner review, 4 intrinsics, 5 extrinsics, 6 depth,
7 save. Going to a page runs what it needs (detection, calibration, error tables) as a queue of
steps on the GUI's one job runner (:class:`~plantreg_gui.gui.workers.Jobs`), one at a time; the page is shown at once
and fills in when the results arrive. Back always works; Cancel stops the running step and
clears the queue. The wizard holds no computation: :mod:`.jobs` calls the engine.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Callable

import numpy as np
from PySide6.QtCore import QObject, QStandardPaths, QTimer, Signal, Slot
from PySide6.QtWidgets import (QFrame, QHBoxLayout, QLabel, QListWidget, QListWidgetItem, QProgressBar,
                               QPushButton, QScrollArea, QSizePolicy, QStackedWidget, QVBoxLayout, QWidget)

from ..workers import Jobs, Worker, show_error
from . import jobs
from .capture_page import CapturePage
from .depth_page import DepthPage
from .extrinsics_page import ExtrinsicsPage
from .intrinsics_page import IntrinsicsPage
from ...models.calibration import WizardModel
from .review_page import ReviewPage
from .rig_page import RigPage
from .save_page import SavePage

#: What each page needs computed before it can show its content.
STEPS = ("detect", "calibrate", "tables")
NEEDS = {1: (), 2: ("detect",), 3: ("detect",), 4: ("detect", "calibrate"),
         5: ("detect", "calibrate", "tables"), 6: ("detect", "calibrate", "tables"),
         7: ("detect", "calibrate", "tables")}

PROGRESS_HZ = 5


class _Relay(QObject):
    """Carries detections from the worker thread into the GUI thread (queued signal)."""

    detection = Signal(object, object, object)  # session, Detection, thumbnail


class CalibrationWizard(QWidget):
    busy_changed = Signal(bool)
    idle = Signal()
    page_changed = Signal(int)
    saved = Signal(dict)

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.model = WizardModel(self)
        self._worker: Worker | None = None
        self._job_name = ""
        self._queue: list[str] = []
        self._relay = _Relay(self)
        self._relay.detection.connect(self._on_detection)
        self._job_session = None
        self._job_step = ""  # the running step of STEPS, or another job's title
        self.jobs = Jobs(self, on_progress=lambda _title, f, msg: self._on_progress(f, msg),
                         on_cancelled=lambda _title: self._on_cancelled(), on_end=lambda _w: self._on_done())
        self._on_result: Callable[[Any], None] | None = None
        self._demo_folder: Path | None = None
        self._pending_progress: tuple[float, str] | None = None
        self._progress_timer = QTimer(self)
        self._progress_timer.setInterval(1000 // PROGRESS_HZ)
        self._progress_timer.timeout.connect(self._show_progress)
        self.last_error: str | None = None

        root = QHBoxLayout(self)
        self.steps = QListWidget()
        self.steps.setFixedWidth(190)
        self.steps.setStyleSheet("QListWidget { font-size: 10.5pt; } QListWidget::item { padding: 7px; }")
        root.addWidget(self.steps)
        right = QVBoxLayout()
        root.addLayout(right, 1)
        self.heading = QLabel()
        self.heading.setStyleSheet("font-size: 14pt; font-weight: bold; padding: 2px;")
        right.addWidget(self.heading)
        self.stack = QStackedWidget()
        right.addWidget(self.stack, 1)

        # pages see the model and this wizard only through the WizardActions interface (page.py)
        self.pages = [cls(self.model, self) for cls in (RigPage, CapturePage, ReviewPage, IntrinsicsPage,
                                                         ExtrinsicsPage, DepthPage, SavePage)]
        for i, p in enumerate(self.pages):
            # a page wider or taller than the window scrolls: the window fits half a 1920 px
            # screen or a 1280 x 720 laptop whatever the page's tables need
            sc = QScrollArea()
            sc.setWidget(p)
            sc.setWidgetResizable(True)
            sc.setFrameShape(QFrame.Shape.NoFrame)
            self.stack.addWidget(sc)
            QListWidgetItem(f"{i + 1}  {p.title}", self.steps)
        self.steps.currentRowChanged.connect(lambda r: self.go_to_page(r + 1) if r >= 0 else None)

        bar = QHBoxLayout()
        self.status = QLabel("")
        self.status.setMinimumWidth(260)
        # progress text must not change the layout: a relayout repaints (and re-renders) every page
        self.status.setSizePolicy(QSizePolicy.Policy.Ignored, QSizePolicy.Policy.Preferred)
        self.progress = QProgressBar()
        self.progress.setRange(0, 1000)
        self.progress.setTextVisible(True)
        self.cancel_btn = QPushButton("Cancel")
        self.cancel_btn.clicked.connect(self.cancel)
        self.back_btn = QPushButton("◀ Back")
        self.next_btn = QPushButton("Next ▶")
        self.back_btn.clicked.connect(lambda: self.go_to_page(self.page - 1))
        self.next_btn.clicked.connect(self._next)
        bar.addWidget(self.status, 1)
        bar.addWidget(self.progress, 1)
        bar.addWidget(self.cancel_btn)
        bar.addSpacing(20)
        bar.addWidget(self.back_btn)
        bar.addWidget(self.next_btn)
        right.addLayout(bar)
        self.page = 0
        self.go_to_page(1)
        self._set_busy(False)

    # ------------------------------------------------------------------ contract with the main window
    def load_demo(self, folder: Path | None = None) -> None:
        """Write the demo (as ``plantreg demo``) on a worker into the cache, then open its
        calibration session."""
        if folder is None:
            base = QStandardPaths.writableLocation(QStandardPaths.StandardLocation.CacheLocation) or "."
            folder = Path(base) / "demo"
        self._demo_folder = Path(folder)
        self._start("Writing the demo session", jobs.demo_job, (self._demo_folder,),
                    lambda path: self.open_session(path, resume=False))

    def open_session(self, path: str | Path, resume: bool = True) -> bool:
        """Open a capture session folder; detection starts at once. With ``resume``, go back to
        the page the session was left on."""
        from ...core.calibration import Session
        from ...core.errors import PlantregError

        try:
            s = Session.load(Path(path))
        except PlantregError as e:
            self.last_error = str(e)
            show_error(self, "Cannot open the session", str(e))
            return False
        self.set_session(s)
        page = int(s.review.get("wizard_page", 1) or 1) if resume else 1
        if page > 1 and self.page <= 1:
            self.go_to_page(page)
        return True

    def set_session(self, session) -> None:
        if self._worker is not None and self._job_session is not None:
            self._worker.cancel()  # work on the previous session: its results are dropped
        self.model.set_session(session)
        self._update_nav()
        if session.poses:
            from ...core.jobs.process_job import warm_up

            warm_up()  # the calibration's process starts importing while corners are detected
            self._ensure(("detect",))

    def go_to_page(self, n: int) -> None:
        """Show page ``n`` (1-7) and run, on workers, what it needs (detection, calibration, tables)."""
        n = max(1, min(len(self.pages), int(n)))
        if n != self.page:
            self.page = n
            self.stack.setCurrentIndex(n - 1)
            self.steps.blockSignals(True)
            self.steps.setCurrentRow(n - 1)
            self.steps.blockSignals(False)
            self.heading.setText(f"Step {n} of {len(self.pages)}: {self.pages[n - 1].title}")
            self.model.set_wizard_page(n)
            self.page_changed.emit(n)
        self._ensure(NEEDS[n])
        self._update_nav()

    def is_busy(self) -> bool:
        return (self._worker is not None) or bool(self._queue)

    def page_busy(self) -> bool:
        """Busy with work the current page needs (see NEEDS): detection running in the background
        does not make page 1 busy; writing the demo or saving always does."""
        needs = set(NEEDS[self.page])
        running = self._worker is not None and (self._job_step in needs or self._job_step not in STEPS)
        return running or any(s in needs for s in self._queue)

    def shutdown(self) -> None:
        """Cancel and wait for all work; close the 3D view (safe to call twice)."""
        self._queue.clear()
        w = self._worker
        if w is not None:
            w.wait(60000)
            self._worker = None
        self._set_busy(False)
        for p in self.pages:
            if hasattr(p, "shutdown"):
                p.shutdown()
            v = getattr(p, "view3d", None)
            if v is not None:
                v.close_plotter()

    def prepare_screenshot(self) -> None:
        for p in self.pages:
            v = getattr(p, "view3d", None)
            if v is not None and p.isVisible():
                v.prepare_screenshot()

    # ------------------------------------------------------------------ navigation
    def _next(self) -> None:
        if not self.pages[self.page - 1].leave():
            return
        self.go_to_page(self.page + 1)

    def _update_nav(self) -> None:
        self.back_btn.setEnabled(self.page > 1)
        self.next_btn.setEnabled(self.page < len(self.pages) and (self.page > 1 or self.model.session is not None))

    def show_view(self, camera: str, pose: str) -> None:
        """Open one image in the corner review (page 3)."""
        self.go_to_page(3)
        self.model.select_view((pose, camera))

    # ------------------------------------------------------------------ actions the pages ask for
    def run_detection(self, keys: set | None = None) -> None:
        """Detect corners in ``keys`` (all images of the session if None)."""
        if self.model.session is None or self.is_busy():
            return
        if keys is None:
            self.model.clear_detections()
        self._start_detection(keys, self.model.options())

    def redetect(self, key, options) -> None:
        """Detect one image again with new options (kept in the session's review)."""
        if self.model.session is None or self.is_busy():
            return
        self.model.set_options(key, options)
        self._start_detection({key}, {key: options})

    def set_detector(self, detector: str) -> None:
        """Detect every image again with ``detector`` (``"auto"`` or ``"classic"``), kept in the
        session's review; the current page refills when the work is done."""
        if self.model.session is None or self.is_busy():
            return
        if self.model.set_detector(detector):
            self.run_detection()
            self._ensure(NEEDS[self.page])

    def recalibrate(self) -> None:
        if self.model.session is None:
            return
        self.model.invalidate_calibration()
        self._ensure(["detect", "calibrate"] + (["tables"] if self.page >= 5 else []))

    def save_outputs(self, rig_path: Path, report_path: Path | None, roi_min: np.ndarray, roi_max: np.ndarray) -> None:
        """Write the rig file and the report (+ CSV tables) on a worker."""
        m = self.model
        if not m.calibration_ready() or self.is_busy():
            return
        rep = m.report if m.report_ready() else None
        self._start("Saving", jobs.save_job, (m.calibration, m.session, rep, set(m.excluded), rig_path, report_path,
                                              roi_min, roi_max), self._on_saved, session=m.session)

    def cancel(self) -> None:
        self._queue.clear()
        if self._worker is not None:
            self._worker.cancel()
            self.status.setText(f"Cancelling {self._job_name.lower()}…")

    # ------------------------------------------------------------------ the step queue
    def _ensure(self, steps) -> None:
        for s in steps:
            if s not in self._queue:
                self._queue.append(s)
        order = {"detect": 0, "calibrate": 1, "tables": 2}
        self._queue.sort(key=lambda s: order.get(s, 3))
        self._set_busy(self.is_busy())
        if self._worker is None:
            self._run_next()

    def _run_next(self) -> None:
        m = self.model
        while self._queue and self._worker is None:
            step = self._queue.pop(0)
            if m.session is None:
                continue
            if step == "detect":
                missing = {k for k in m.keys() if k not in m.detections}
                if missing:
                    self._start_detection(None if len(missing) == len(m.keys()) else missing, m.options())
            elif step == "calibrate":
                if not m.calibration_ready():
                    self._start("Calibrating", jobs.calibrate_job,
                                (m.session, dict(m.detections), set(m.excluded)), m.set_calibration,
                                session=m.session, step="calibrate")
            elif step == "tables":
                if m.calibration_ready() and not m.report_ready():
                    self._start("Computing error tables", jobs.tables_job,
                                (m.session, m.calibration, dict(m.detections), set(m.excluded)), m.set_report,
                                session=m.session, step="tables")
        if self._worker is None:
            self._set_busy(False)
            self.idle.emit()

    def _start_detection(self, keys, options) -> None:
        session = self.model.session
        relay = self._relay

        def sink(det, thumb) -> None:  # called on the worker thread; the signal is queued
            relay.detection.emit(session, det, thumb)

        self._start("Detecting corners", jobs.detect_job,
                    (session, dict(options), None if keys is None else set(keys), sink),
                    lambda r: self.model.set_board_hint(r["board_hint"]) if keys is None else None,
                    session=session, step="detect")

    def _start(self, title: str, fn: Callable, args: tuple, on_result: Callable[[Any], None] | None,
               session=None, step: str | None = None) -> None:
        """Run ``fn(*args)`` on a worker of the GUI's one job runner (:class:`Jobs`), one job at a
        time; ``on_result(result)`` on success. ``step``: which of STEPS this job is (None: another
        job such as saving). With ``session``, the result is dropped if another session was opened
        meanwhile."""
        if self._worker is not None:
            return
        self.last_error = None
        self._job_session = session
        self._job_name = title
        self._job_step = step or title
        self._on_result = on_result
        w = Worker(fn, *args, parent=self)
        self._worker = w
        self.status.setText(f"{title}…")
        self.progress.setValue(0)
        self._set_busy(True)
        self.jobs.start(w, title, self._on_finished, on_failed=self._on_failed)

    @Slot(object, object, object)
    def _on_detection(self, session, det, thumb) -> None:
        if session is self.model.session:
            self.model.put_detection(det, thumb)

    @Slot(float, str)
    def _on_progress(self, f: float, msg: str) -> None:
        # at most PROGRESS_HZ repaints: every repaint of the window also re-renders the 3D view
        self._pending_progress = (f, msg)
        if not self._progress_timer.isActive():
            self._show_progress()
            self._progress_timer.start()

    def _show_progress(self) -> None:
        if self._pending_progress is None:
            return
        f, msg = self._pending_progress
        self._pending_progress = None
        self.progress.setValue(int(1000 * f))
        self.progress.setFormat(f"{100 * f:.0f} %")
        self.status.setText(f"{self._job_name}: {msg}" if msg else self._job_name)

    @Slot(object)
    def _on_finished(self, result) -> None:
        self._drop_pending_progress()
        self.status.setText(f"{self._job_name}: done")
        self.progress.setValue(1000)
        cb = self._on_result
        if self._job_session is not None and self._job_session is not self.model.session:
            return
        if cb is not None:
            cb(result)

    @Slot(str, str)
    def _on_failed(self, message: str, details: str) -> None:
        self._queue.clear()
        self._drop_pending_progress()
        self.last_error = message
        self.status.setText(f"{self._job_name} failed")
        show_error(self, f"{self._job_name} failed", message, details)

    @Slot()
    def _on_cancelled(self) -> None:
        if self._job_session is not None and self._job_session is not self.model.session:
            return  # superseded by another session: its queued steps stay
        self._queue.clear()
        self._drop_pending_progress()  # a message sent before the cancel must not overwrite it
        self.status.setText(f"{self._job_name}: cancelled")

    def _drop_pending_progress(self) -> None:
        self._pending_progress = None
        self._progress_timer.stop()

    @Slot()
    def _on_done(self) -> None:
        w = self._worker
        self._worker = None
        if w is not None:
            w.deleteLater()
        self._run_next()

    def _on_saved(self, paths: dict) -> None:
        self.model.set_saved_paths(paths)
        self.saved.emit(dict(paths))

    def _set_busy(self, busy: bool) -> None:
        self.progress.setVisible(busy)
        self.cancel_btn.setEnabled(busy and self._worker is not None)
        self.busy_changed.emit(busy)
