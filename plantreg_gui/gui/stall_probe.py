"""Measuring GUI-thread stalls: the one probe that tests and benchmarks share.

A :class:`StallProbe` runs a 20 ms ``QTimer`` on the GUI thread and records the gaps between its
ticks. A gap much longer than the interval means the event loop was blocked (work on the GUI
thread, or a worker thread holding the GIL). Use it as a context manager around scripted work::

    with StallProbe() as probe:
        ...  # drive the GUI, e.g. qtbot.waitUntil(...)
    probe.max_gap   # seconds
"""

from __future__ import annotations

import time

from PySide6.QtCore import QTimer


class StallProbe:
    """A 20 ms QTimer on the GUI thread recording the largest gap between its ticks."""

    def __init__(self, interval_ms: int = 20) -> None:
        self.interval_s = interval_ms / 1000.0
        self.max_gap = 0.0
        self.ticks = 0
        self.gaps: list[float] = []
        self._last = time.perf_counter()
        self.timer = QTimer()
        self.timer.setInterval(interval_ms)
        self.timer.timeout.connect(self._tick)

    def _tick(self) -> None:
        now = time.perf_counter()
        gap = now - self._last
        self.gaps.append(gap)
        self.max_gap = max(self.max_gap, gap)
        self._last = now
        self.ticks += 1

    def start(self) -> "StallProbe":
        self._last = time.perf_counter()
        self.timer.start()
        return self

    def stop(self) -> None:
        self.timer.stop()

    def stalls(self, threshold_s: float = 0.2) -> list[float]:
        """The gaps longer than ``threshold_s`` seconds."""
        return [g for g in self.gaps if g > threshold_s]

    def __enter__(self) -> "StallProbe":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()
