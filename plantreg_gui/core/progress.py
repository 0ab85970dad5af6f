"""Progress reporting and cancellation for long core routines.

Core routines take ``progress: Reporter | None``. They call ``progress(fraction, message)``
(fraction in [0, 1] of *their own* work) and wrap stages in ``with progress.stage(name)``.
Every call is a cancellation point: if the :class:`CancelToken` was cancelled, it raises
:class:`~plantreg_gui.core.errors.Cancelled`. No Qt here; the GUI wraps a Reporter
around a worker's signal, the CLI around a stderr printer.
"""

from __future__ import annotations

import threading
import time
from contextlib import contextmanager
from typing import Callable, Iterator

from .errors import Cancelled

ProgressCallback = Callable[[float, str], None]


class CancelToken:
    """Thread-safe flag set by the UI, polled by the worker."""

    def __init__(self) -> None:
        self._event = threading.Event()

    def cancel(self) -> None:
        self._event.set()

    @property
    def cancelled(self) -> bool:
        return self._event.is_set()

    def raise_if_cancelled(self) -> None:
        if self._event.is_set():
            raise Cancelled()


class Reporter:
    """Maps a routine's local progress onto a callback and checks for cancellation.

    ``sub(a, b)`` gives a child reporter whose [0, 1] maps to [a, b] of this one, so nested
    routines need not know where they sit in the whole job. Stage timings are collected in
    ``timings`` (seconds, shared with children).
    """

    def __init__(
        self,
        callback: ProgressCallback | None = None,
        cancel: CancelToken | None = None,
        *,
        _span: tuple[float, float] = (0.0, 1.0),
        _timings: dict[str, float] | None = None,
    ) -> None:
        self.callback = callback
        self.cancel = cancel or CancelToken()
        self._span = _span
        self.timings: dict[str, float] = {} if _timings is None else _timings

    def __call__(self, fraction: float, message: str = "") -> None:
        self.cancel.raise_if_cancelled()
        if self.callback is not None:
            a, b = self._span
            f = min(max(float(fraction), 0.0), 1.0)
            self.callback(a + (b - a) * f, message)

    def check(self) -> None:
        """A cancellation point that reports nothing."""
        self.cancel.raise_if_cancelled()

    def sub(self, start: float, end: float) -> "Reporter":
        a, b = self._span
        return Reporter(
            self.callback,
            self.cancel,
            _span=(a + (b - a) * start, a + (b - a) * end),
            _timings=self.timings,
        )

    def timed(self, timings: dict[str, float]) -> "Reporter":
        """This reporter (same span, callback and cancellation) recording stage times into
        ``timings`` instead of its own table (e.g. one table per registration)."""
        return Reporter(self.callback, self.cancel, _span=self._span, _timings=timings)

    @contextmanager
    def stage(self, name: str, start: float = 0.0, end: float | None = None) -> Iterator[None]:
        """Time a named stage; reports ``name`` at ``start`` (and at ``end`` if given)."""
        self(start, name)
        t0 = time.perf_counter()
        try:
            yield
        finally:
            self.timings[name] = self.timings.get(name, 0.0) + time.perf_counter() - t0
        if end is not None:
            self(end, name)


def ensure_reporter(progress: Reporter | ProgressCallback | None) -> Reporter:
    if isinstance(progress, Reporter):
        return progress
    return Reporter(progress)
