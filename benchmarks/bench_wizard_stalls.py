"""GUI-thread stalls of the calibration wizard, per scripted step.

    PYTHONPATH=. .venv/bin/python benchmarks/bench_wizard_stalls.py [--set demo|stereo|both]
                                                                    [--data DIR] [--trace]

A :class:`~stall_probe.StallProbe` (20 ms timer on the GUI thread) runs while
the wizard, shown on screen (use ``xvfb-run -a`` without a display), does each step as a
technician would: open a session and detect corners (page 2), calibrate (page 4), compute the
error tables (page 5), go to page 7; then a fresh wizard *resumes* the saved session on page 7
(detection + calibration + tables in one go). Printed per step: the largest gap between ticks
(ms), the number of gaps over 200 ms, and the step's wall time.

Sets: ``demo`` = the synthetic calibration session of ``plantreg demo`` (4 cameras with a ToF
depth camera; rendered once into ``--data``); ``stereo`` = OpenCV's stereo sample in
``../shared/data/opencv-stereo`` (13 real pairs, no depth).

``--trace`` samples the Python stacks of every thread whenever the GUI thread has been stalled
for more than 120 ms and prints the most frequent innermost frames: where the time went.

Timings depend on the machine's load; run it on an idle machine to compare with the 200 ms goal.
Not part of the test run.
"""

from __future__ import annotations

import argparse
import collections
import shutil
import sys

sys.path.insert(0, str(__import__("pathlib").Path(__file__).resolve().parents[1] / "tests"))  # stall_probe
import tempfile
import threading
import time
import traceback
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


class _Watchdog:
    """Samples all threads' stacks while the GUI thread is stalled (for --trace)."""

    def __init__(self, probe, threshold_s: float = 0.12) -> None:
        self.probe, self.threshold = probe, threshold_s
        self.samples: collections.Counter = collections.Counter()
        self._stop = threading.Event()
        self._main = threading.main_thread().ident
        self._t = threading.Thread(target=self._run, daemon=True)

    def start(self) -> "_Watchdog":
        self._t.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        self._t.join()

    def _run(self) -> None:
        while not self._stop.wait(0.03):
            if time.perf_counter() - self.probe._last < self.threshold:
                continue
            for tid, frame in sys._current_frames().items():
                if tid == threading.get_ident():
                    continue
                st = traceback.extract_stack(frame)
                mine = [f for f in st if "plantreg_gui" in f.filename] or st
                where = "main" if tid == self._main else "worker"
                inner = st[-1]
                key = (f"[{where}] {Path(mine[-1].filename).name}:{mine[-1].lineno} {mine[-1].name}"
                       f"  <- innermost {Path(inner.filename).name}:{inner.lineno} {inner.name}")
                self.samples[key] += 1


def _run_until(app, cond, timeout_s: float) -> None:
    from PySide6.QtCore import QEventLoop, QTimer

    loop = QEventLoop()
    t_end = time.perf_counter() + timeout_s
    timer = QTimer()
    timer.setInterval(10)
    timer.timeout.connect(lambda: loop.quit() if cond() or time.perf_counter() > t_end else None)
    timer.start()
    loop.exec()
    timer.stop()
    if not cond():
        raise TimeoutError("step did not finish in time")


def _step(app, name: str, action, cond, trace: bool, rows: list) -> None:
    from stall_probe import LoadControl, StallProbe

    probe = StallProbe()
    t0 = time.perf_counter()
    with LoadControl() as control, probe:  # the control: what the machine's load did to any process
        dog = _Watchdog(probe).start() if trace else None
        action()
        _run_until(app, cond, 600)
        if dog is not None:
            dog.stop()
    wall = time.perf_counter() - t0
    rows.append((name, probe.max_gap * 1000, len(probe.stalls(0.2)), wall))
    print(f"  {name:<44} max gap {probe.max_gap * 1000:7.0f} ms   GUI CPU {probe.max_cpu * 1000:4.0f} ms "
          f"(in that gap {probe.cpu_at_max_gap * 1000:4.0f})   gaps>200ms {len(probe.stalls(0.2)):3d}   "
          f"wall {wall:6.1f} s   control stretch {control.stretch:5.1f}x (gap / stretch "
          f"{probe.max_gap * 1000 / control.stretch:5.0f} ms)", flush=True)
    if dog is not None:
        for k, n in dog.samples.most_common(8):
            print(f"      {n:4d} x {k}")


def bench_set(app, label: str, source: Path, trace: bool) -> list:
    from plantreg_gui.gui.calibration.wizard import CalibrationWizard

    print(f"{label}: {source}")
    work = Path(tempfile.mkdtemp(prefix="bench-wizard-"))
    folder = work / "session"
    shutil.copytree(source, folder)
    rows: list = []
    w = CalibrationWizard()
    w.resize(1400, 900)
    w.show()
    idle = lambda: not w.is_busy()  # noqa: E731
    try:
        _step(app, "open session + detect (page 2)", lambda: (w.open_session(folder, resume=False), w.go_to_page(2)),
              idle, trace, rows)
        _step(app, "calibrate (page 4)", lambda: w.go_to_page(4), idle, trace, rows)
        rp = w.pages[2]
        if hasattr(rp, "undistort"):  # the corner review's residual vectors and undistorted view
            cam = w.model.session.camera_names[0]
            pose = next(p for (p, c), d in w.model.detections.items() if c == cam and d.status == "found")
            _step(app, "corner review: residuals, undistorted", lambda: (w.show_view(cam, pose),
                  rp.undistort.setChecked(True)), lambda: rp.shown_undistorted, trace, rows)
            rp.undistort.setChecked(False)
        view3d = w.pages[4].view3d  # its scene is drawn in stages after the tables: wait for the last
        _step(app, "error tables (page 5)", lambda: w.go_to_page(5), lambda: idle() and not view3d.building,
              trace, rows)
        _step(app, "depth page (page 6)", lambda: w.go_to_page(6), idle, trace, rows)
        _step(app, "save page (page 7)", lambda: w.go_to_page(7), idle, trace, rows)
    finally:
        w.shutdown()
        w.close()
        w.deleteLater()
    w2 = CalibrationWizard()
    w2.resize(1400, 900)
    w2.show()
    try:
        _step(app, "resume on page 7 (detect+calibrate+tables)", lambda: w2.open_session(folder),
              lambda: not w2.is_busy(), trace, rows)
    finally:
        w2.shutdown()
        w2.close()
        w2.deleteLater()
    shutil.rmtree(work, ignore_errors=True)
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--set", choices=("demo", "stereo", "both"), default="both")
    ap.add_argument("--data", type=Path, default=Path(tempfile.gettempdir()) / "plantreg-bench-wizard")
    ap.add_argument("--shared", type=Path, default=ROOT.parent / "shared" / "data")
    ap.add_argument("--trace", action="store_true", help="sample stacks during stalls")
    a = ap.parse_args(argv)

    from PySide6.QtWidgets import QApplication

    app = QApplication.instance() or QApplication(sys.argv[:1])
    from plantreg_gui.gui.startup import preload

    print(f"start-up: 3D stack imported in {preload():.2f} s (as plantreg-gui does, behind its splash)")
    sets = []
    if a.set in ("demo", "both"):
        demo = a.data / "calibration"
        if not (demo / "session.json").is_file():
            from plantreg_gui.core.calibration.synthetic import write_calibration_session
            from plantreg_gui.core.synthetic.demo import demo_rig

            print(f"rendering the demo calibration session into {demo} (not timed) ...", flush=True)
            a.data.mkdir(parents=True, exist_ok=True)
            write_calibration_session(demo_rig("demo"), demo, seed=0, overwrite=True)
        sets.append(("demo", demo))
    if a.set in ("stereo", "both"):
        sets.append(("stereo", a.shared / "opencv-stereo"))
    worst = 0.0
    for label, src in sets:
        for _name, gap, _n, _wall in bench_set(app, label, src, a.trace):
            worst = max(worst, gap)
    print(f"largest GUI-thread gap over all steps: {worst:.0f} ms (goal: <= 200 ms on an idle 2-core machine)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
