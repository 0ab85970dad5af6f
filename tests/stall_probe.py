"""Measuring GUI-thread stalls: the one probe that tests and benchmarks share.

A :class:`StallProbe` runs a 20 ms ``QTimer`` on the GUI thread and records the gaps between its
ticks. A gap much longer than the interval means the event loop was blocked (work on the GUI
thread, or a worker thread holding the GIL). Use it as a context manager around scripted work::

    with StallProbe() as probe:
        ...  # drive the GUI, e.g. qtbot.waitUntil(...)
    probe.max_gap   # seconds
"""

from __future__ import annotations

import sys
import threading
import time
import traceback

from PySide6.QtCore import QTimer


class StallProbe:
    """A 20 ms QTimer on the GUI thread recording the largest gap between its ticks."""

    def __init__(self, interval_ms: int = 20, trace_after_s: float | None = None) -> None:
        """``trace_after_s``: if set, a watchdog thread records the stacks of all threads whenever
        the GUI thread has not ticked for that long (see :attr:`traces`), to say *what* stalled."""
        self.interval_s = interval_ms / 1000.0
        self.max_gap = 0.0
        self.ticks = 0
        self.gaps: list[float] = []
        self.traces: list[str] = []
        self._last = time.perf_counter()
        self._trace_after = trace_after_s
        self._watchdog: threading.Thread | None = None
        self._stop = threading.Event()
        self._gui_ident = threading.get_ident()
        self.timer = QTimer()
        self.timer.setInterval(interval_ms)
        self.timer.timeout.connect(self._tick)

    def _watch(self) -> None:
        traced_at = None
        while not self._stop.wait(self._trace_after / 4):
            last = self._last
            if time.perf_counter() - last > self._trace_after and traced_at != last:
                traced_at = last
                frames = sys._current_frames()
                names = {t.ident: t.name for t in threading.enumerate()}
                parts = [f"GUI thread silent for {time.perf_counter() - last:.2f} s"]
                for ident, frame in frames.items():
                    if ident == threading.get_ident():
                        continue
                    who = "GUI thread" if ident == self._gui_ident else names.get(ident, ident)
                    parts.append(f"--- {who}\n" + "".join(traceback.format_stack(frame)[-12:]))
                self.traces.append("\n".join(parts))

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
        if self._trace_after:
            self._stop.clear()
            self._watchdog = threading.Thread(target=self._watch, name="stall-watchdog", daemon=True)
            self._watchdog.start()
        return self

    def stop(self) -> None:
        self.timer.stop()
        if self._watchdog is not None:
            self._stop.set()
            self._watchdog.join()
            self._watchdog = None

    def stalls(self, threshold_s: float = 0.2) -> list[float]:
        """The gaps longer than ``threshold_s`` seconds."""
        return [g for g in self.gaps if g > threshold_s]

    def __enter__(self) -> "StallProbe":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()
