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
        # the GUI thread's own CPU time between two ticks (time.thread_time): the work an event
        # did, far less inflated by other processes than the wall gap (a wait for the GIL or for
        # the X server is in the wall gap only)
        self.max_cpu = 0.0
        self.cpu_at_max_gap = 0.0
        self._last_cpu = time.thread_time()
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
        cpu_now = time.thread_time()
        cpu = cpu_now - self._last_cpu
        self.gaps.append(gap)
        if gap > self.max_gap:
            self.max_gap, self.cpu_at_max_gap = gap, cpu
        self.max_cpu = max(self.max_cpu, cpu)
        self._last, self._last_cpu = now, cpu_now
        self.ticks += 1

    def start(self) -> "StallProbe":
        self._last = time.perf_counter()
        self._last_cpu = time.thread_time()
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


# ---------------------------------------------------------------------- a control for a busy machine
_CONTROL = """
import os, sys, time
flag, worst = sys.argv[1], 0.0
print("ready", flush=True)
while not os.path.exists(flag):
    t0 = time.perf_counter()
    c0 = time.process_time()
    while time.process_time() - c0 < 0.02:  # 20 ms of CPU work, like an event-loop slot ...
        pass
    time.sleep(0.02)  # ... then idle
    worst = max(worst, time.perf_counter() - t0 - 0.04)
print(worst, flush=True)
"""


class LoadControl:
    """A control measured in the same test, over the same interval as a :class:`StallProbe`: a
    process of the same priority (no Qt, no GIL shared with the GUI) alternating 20 ms of CPU work
    and 20 ms of sleep, like an event loop, recording how much longer than 40 ms its worst cycle
    took (:attr:`worst`, seconds).

    On a machine where other work wants the CPU, every process waits for it: a 20 ms slot that
    takes 20 + ``worst`` ms says the machine stretched CPU work by ``1 + worst / 0.02`` over this
    interval (:attr:`stretch`; about 1 on an idle machine). :meth:`allowed` scales a GUI-thread gap
    goal by it, so a test asserts "no stall beyond what the machine did to everyone" and passes on
    a busy machine, while a freeze of our own (seconds of work on the GUI thread, a worker holding
    the GIL) fails it on an idle one. Latency itself is measured by the benchmarks
    (``benchmarks/bench_gui_stalls.py``, ``bench_wizard_stalls.py``) on an idle machine."""

    def __init__(self) -> None:
        import subprocess
        import tempfile

        self._dir = tempfile.mkdtemp(prefix="plantreg-control-")
        self.flag = f"{self._dir}/stop"
        self.worst: float | None = None
        self.proc = subprocess.Popen([sys.executable, "-c", _CONTROL, self.flag], stdout=subprocess.PIPE, text=True)
        assert self.proc.stdout.readline().strip() == "ready"

    def stop(self) -> float:
        import shutil

        if self.worst is None:
            with open(self.flag, "w") as f:
                f.write("stop")
            out, _ = self.proc.communicate(timeout=60)
            self.worst = float(out.strip())
            shutil.rmtree(self._dir, ignore_errors=True)
        return self.worst

    @property
    def stretch(self) -> float:
        return 1.0 + self.stop() / 0.02

    def allowed(self, goal_s: float) -> float:
        """``goal_s`` (the gap allowed on an idle machine) at a stretch of 1; beyond, the stretch's
        excess counts twice: the GUI thread also waits for the GIL hand-overs of its own process's
        worker threads, which a busy machine slows as well (measured with two CPU hogs at a load
        of 12 on 2 cores: a stretch of 18, a 3.6 s gap where the goal is 0.2 s)."""
        return goal_s * (2.0 * self.stretch - 1.0)

    def __enter__(self) -> "LoadControl":
        return self

    def __exit__(self, *exc) -> None:
        self.stop()
