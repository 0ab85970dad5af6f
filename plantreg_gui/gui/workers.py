"""Running core routines off the GUI thread.

A core routine takes a ``progress: Reporter`` keyword. :class:`Worker` runs it on a QThread,
turns its progress calls into a Qt signal, and cancels it through the Reporter's token (the
routine raises ``Cancelled`` at its next progress call). Results and errors come back as signals
on the GUI thread; :func:`show_error` is the one place where errors become dialogs.
"""

from __future__ import annotations

import traceback
import weakref
from typing import Any, Callable

from PySide6.QtCore import QObject, QThread, Signal, Slot
from PySide6.QtWidgets import QMessageBox, QWidget

from ..core.errors import Cancelled, PlantregError
from ..core.progress import CancelToken, Reporter


class _Runner(QObject):
    progress = Signal(float, str)
    finished = Signal(object)
    failed = Signal(str, str)  # (message, details)
    cancelled = Signal()

    def __init__(self, fn: Callable[..., Any], args: tuple, kwargs: dict, token: CancelToken):
        super().__init__()
        self._fn, self._args, self._kwargs, self._token = fn, args, kwargs, token

    @Slot()
    def run(self) -> None:
        reporter = Reporter(lambda f, m: self.progress.emit(f, m), self._token)
        try:
            result = self._fn(*self._args, progress=reporter, **self._kwargs)
        except Cancelled:
            self.cancelled.emit()
        except PlantregError as e:
            self.failed.emit(str(e), "")
        except MemoryError:
            self.failed.emit("Out of memory. Close other views or use a smaller target camera.", traceback.format_exc())
        except Exception as e:  # a bug: show it readably, keep the details for a report
            self.failed.emit(f"Unexpected error: {type(e).__name__}: {e}", traceback.format_exc())
        else:
            self.finished.emit(result)


class Worker(QObject):
    """Run ``fn(*args, progress=Reporter, **kwargs)`` on its own thread.

    Signals (delivered on the GUI thread): ``progress(fraction, message)``, ``finished(result)``,
    ``failed(message, details)``, ``cancelled()``, and ``done()`` after any of the last three.
    Keep a reference until ``done``.
    """

    progress = Signal(float, str)
    finished = Signal(object)
    failed = Signal(str, str)
    cancelled = Signal()
    done = Signal()

    def __init__(self, fn: Callable[..., Any], *args: Any, parent: QObject | None = None, **kwargs: Any):
        super().__init__(parent)
        self.token = CancelToken()
        self._thread = QThread()
        self._runner = _Runner(fn, args, kwargs, self.token)
        self._runner.moveToThread(self._thread)
        self._thread.started.connect(self._runner.run)
        self._runner.progress.connect(self.progress)
        self._runner.finished.connect(self._on_finished)
        self._runner.failed.connect(self._on_failed)
        self._runner.cancelled.connect(self._on_cancelled)
        self._running = False

    #: workers whose thread has started and not yet ended (for leak checks in tests)
    running: "weakref.WeakSet[Worker]" = weakref.WeakSet()

    def start(self) -> "Worker":
        self._running = True
        Worker.running.add(self)
        self._thread.start()
        return self

    def cancel(self) -> None:
        self.token.cancel()

    #: cancelled because a newer job replaced it: runners report no "cancelled" for it
    superseded = False

    def supersede(self) -> None:
        self.superseded = True
        self.token.cancel()

    def is_running(self) -> bool:
        return self._running

    def wait(self, ms: int = 30000) -> bool:
        """Cancel and wait for the thread to end (for closing the window).

        The thread's event loop is told to quit here, not by the result slots: those run on the
        GUI thread, which is the one blocked in this call.
        """
        self.token.cancel()
        self._thread.quit()
        return self._thread.wait(ms)

    def _end(self) -> None:
        self._running = False
        Worker.running.discard(self)
        self._thread.quit()
        self._thread.wait()
        self.done.emit()

    @Slot(object)
    def _on_finished(self, result: object) -> None:
        self._thread.quit()
        self._thread.wait()
        try:  # a slot that raises must not leave the job running forever (no done())
            self.finished.emit(result)
        finally:
            self._end()

    @Slot(str, str)
    def _on_failed(self, message: str, details: str) -> None:
        self._thread.quit()
        self._thread.wait()
        try:  # a slot that raises must not leave the job running forever (no done())
            self.failed.emit(message, details)
        finally:
            self._end()

    @Slot()
    def _on_cancelled(self) -> None:
        self._thread.quit()
        self._thread.wait()
        try:
            self.cancelled.emit()
        finally:
            self._end()


#: (title, message) of every error shown: an unattended ``--screenshot`` run reports them and
#: fails instead of exiting 0 with a dialog nobody sees.
SHOWN_ERRORS: list[tuple[str, str]] = []


def show_error(parent: QWidget | None, title: str, message: str, details: str = "") -> None:
    """The one place where errors become dialogs (non-modal-safe: uses open() under tests)."""
    SHOWN_ERRORS.append((title, message))
    box = QMessageBox(QMessageBox.Icon.Warning, title, message, QMessageBox.StandardButton.Ok, parent)
    if details:
        box.setDetailedText(details)
    box.setObjectName("errorDialog")
    box.open()


class Jobs:
    """The one GUI job runner: starts :class:`Worker` s, routes their outcome and keeps them until
    they are done. A window or page gives its own ways of showing progress and cancellation; an
    error always becomes a dialog (:func:`show_error`).

    ``on_progress(title, fraction, message)``, ``on_cancelled(title)``, ``on_end(worker)`` after
    any outcome (the worker is no longer listed then). ``bool(jobs)``: any worker still running.
    """

    def __init__(self, parent: QWidget | None, on_progress: Callable[[str, float, str], None] | None = None,
                 on_cancelled: Callable[[str], None] | None = None,
                 on_end: Callable[[Worker], None] | None = None):
        self.parent = parent
        self.on_progress, self.on_cancelled, self.on_end = on_progress, on_cancelled, on_end
        self.workers: list[Worker] = []

    def start(self, w: Worker, title: str, on_done: Callable[[Any], None], error_title: str | None = None,
              on_end: Callable[[Worker], None] | None = None,
              on_failed: Callable[[str, str], None] | None = None, background: bool = False) -> Worker:
        """Start ``w``: ``on_done(result)`` on success; a failure is shown as ``error_title``
        (default "<title> failed") unless ``on_failed(message, details)`` handles it; ``on_end(w)``
        (else the runner's) after any outcome. ``background``: no progress or cancel reports (a
        preview the page refreshes by itself)."""
        self.workers.append(w)
        if self.on_progress is not None and not background:
            w.progress.connect(lambda f, m, t=title: self.on_progress(t, f, m))
        w.finished.connect(on_done)
        if on_failed is not None:
            w.failed.connect(on_failed)
        else:
            w.failed.connect(lambda msg, det, t=error_title or f"{title} failed": show_error(self.parent, t, msg, det))
        if self.on_cancelled is not None and not background:
            w.cancelled.connect(lambda t=title, w=w: None if w.superseded else self.on_cancelled(t))
        end = on_end or self.on_end
        w.done.connect(lambda w=w: self._done(w, end))
        w.start()
        return w

    def _done(self, w: Worker, end: Callable[[Worker], None] | None) -> None:
        if w in self.workers:
            self.workers.remove(w)
        if end is not None:
            end(w)

    def __bool__(self) -> bool:
        return bool(self.workers)

    def __contains__(self, w: object) -> bool:
        return w in self.workers

    def __iter__(self):
        return iter(list(self.workers))

    def cancel_all(self) -> None:
        for w in list(self.workers):
            w.cancel()

    def wait_all(self, ms: int = 30000) -> None:
        """Cancel every worker and wait for its thread (closing a window)."""
        for w in list(self.workers):
            w.cancel()
        for w in list(self.workers):
            w.wait(ms)
