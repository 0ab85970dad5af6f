"""GUI-thread stalls per scripted step: the longest gap of a 20 ms timer on the GUI thread.

Usage (under Xvfb on a headless machine)::

    xvfb-run -a python benchmarks/bench_gui_stalls.py [--only NAME ...] [--repeat N]

Each scenario in :data:`SCENARIOS` prepares its widgets (not measured), starts its work and is
measured with :class:`~stall_probe.StallProbe` until its ``done`` predicate holds.
The table prints, per scenario, the wall time, the longest gap, the number of gaps over 200 ms,
and what the progress bar said just before the longest gap (where to look for the cause).
The goal (issue 11) is no gap over 200 ms on an idle 2-core machine; figures on a loaded machine
are inflated by the other processes.

To add a scenario: write ``setup(ctx)``, ``run(ctx)`` and ``done(ctx)`` and add one
:class:`Scenario` line to :data:`SCENARIOS`. ``ctx`` is a :class:`Context` shared by all scenarios
(demo folder, a temporary folder, and widgets created on first use).
"""

from __future__ import annotations

import argparse
import os
import sys

sys.path.insert(0, str(__import__("pathlib").Path(__file__).resolve().parents[1] / "tests"))  # stall_probe
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

os.environ.setdefault("QT_API", "pyside6")


@dataclass
class Context:
    app: Any
    tmp: Path
    demo: Path | None = None
    widgets: dict[str, Any] = field(default_factory=dict)

    def demo_folder(self) -> Path:
        if self.demo is None:
            from plantreg_gui.core.synthetic import write_demo

            self.demo = self.tmp / "demo"
            write_demo(self.demo, calibration=False)
        return self.demo

    def widget(self, key: str, make: Callable[[], Any], fresh: bool = False):
        """The shown widget ``key`` (1400 x 900), made by ``make()`` on first use; with ``fresh``
        the old one is shut down and a new one made."""
        old = self.widgets.get(key)
        if old is not None and not fresh:
            return old
        if old is not None:
            old.shutdown()
            old.close()
            old.deleteLater()
        w = make()
        w.resize(1400, 900)
        w.show()
        self.widgets[key] = w
        return w

    def workspace(self, fresh: bool = False):
        """A shown registration workspace (a new one with ``fresh``)."""
        from PySide6.QtCore import QSettings

        from plantreg_gui.gui.registration.workspace import RegistrationWorkspace

        for fmt in (QSettings.Format.NativeFormat, QSettings.Format.IniFormat):  # keep the user's settings out
            QSettings.setPath(fmt, QSettings.Scope.UserScope, str(self.tmp / "qsettings"))
        return self.widget("workspace", RegistrationWorkspace, fresh)

    def wait(self, pred: Callable[[], bool], timeout: float = 600.0) -> None:
        from PySide6.QtCore import QEventLoop, QTimer

        t0 = time.monotonic()
        while not pred():
            if time.monotonic() - t0 > timeout:
                raise TimeoutError("scenario did not finish")
            loop = QEventLoop()
            QTimer.singleShot(10, loop.quit)
            loop.exec()

    def progress_text(self) -> str:
        """What the busy widgets' progress bars say now (for locating a stall)."""
        texts = []
        for w in self.widgets.values():
            bar = getattr(w, "progress", None)
            if bar is not None and hasattr(bar, "isVisible") and bar.isVisible():
                texts.append(bar.format().replace("%p%", "").replace("%%", "%").strip())
        return "; ".join(texts) or "(no progress shown)"


@dataclass(frozen=True)
class Scenario:
    name: str
    setup: Callable[[Context], None]     # not measured
    run: Callable[[Context], None]       # starts the work (measured from here)
    done: Callable[[Context], bool]      # the work is over


# ---------------------------------------------------------------------- workspace scenarios
def _ws_open(ctx: Context) -> None:
    w = ctx.workspace(fresh=True)
    w.open_rig(ctx.demo_folder() / "rig.json")
    w.open_recording(ctx.demo_folder() / "recording")
    ctx.wait(lambda: not w.is_busy())


def _ws_open_setup(ctx: Context) -> None:
    ctx.demo_folder()
    ctx.workspace(fresh=True)


def _ws_open_run(ctx: Context) -> None:
    w = ctx.workspace()
    w.open_rig(ctx.demo_folder() / "rig.json")
    w.open_recording(ctx.demo_folder() / "recording")


def _ws_registered(ctx: Context) -> None:
    w = ctx.workspace()
    if w.result is None or w.result.target != "ir":
        _ws_open(ctx)
        w = ctx.workspace()
        w.run_registration("ir")
        ctx.wait(lambda: w.result is not None and not w.is_busy())


def _ws_idle(ctx: Context) -> bool:
    return not ctx.workspace().is_busy()


def _ws_register_run(ctx: Context, target: str) -> None:
    ctx.workspace().run_registration(target)


def _ws_load_demo_setup(ctx: Context) -> None:
    ctx.workspace(fresh=True)


def _ws_load_demo_run(ctx: Context) -> None:
    ctx.workspace().load_demo(target="ir")


def _ws_export_run(ctx: Context) -> None:
    out = ctx.tmp / f"export-{time.monotonic_ns()}"
    ctx.workspace().export(out)


def _ws_switch_views(ctx: Context) -> None:
    w = ctx.workspace()
    for key in ("side-by-side", "mosaic", "masks", "3d", "raw", "side-by-side"):
        w.set_view(key)
        ctx.wait(lambda: True)
        t = time.monotonic()
        ctx.wait(lambda: time.monotonic() - t > 0.2)


def _ws_resize(ctx: Context) -> None:
    """Side by side, then 3D, each resized 1400 x 900 -> 2560 x 1440 -> back, as a window is
    maximised on a large screen (every view re-fits; the 3D view re-renders at the new size)."""
    w = ctx.workspace()
    for key in ("side-by-side", "3d"):
        w.set_view(key)
        ctx.wait(lambda: not getattr(w.cloud_view, "building", False))
        for size in ((2560, 1440), (1400, 900)):
            w.resize(*size)
            t = time.monotonic()
            ctx.wait(lambda: time.monotonic() - t > 0.5)


def _ws_fresh_registered(ctx: Context) -> None:
    """A new workspace showing a registration: its 3D tab has never been shown."""
    ctx.workspace(fresh=True)
    _ws_registered(ctx)
    ctx.workspace().set_view("side-by-side")


def _ws_3d_shown(ctx: Context) -> bool:
    cv = ctx.workspace().cloud_view
    return cv.plotter is not None and not cv.building  # the staged build is complete


# ---------------------------------------------------------------------- landmark page scenarios
REAL = Path(__file__).resolve().parents[1] / "resources" / "plant3dimagereg"


def _lm_files(ctx: Context) -> tuple[Path, Path | None, list[Path]]:
    """(rig, landmarks, recordings): the real plants' landmarks if their data are here, else the demo."""
    if os.environ.get("PLANTREG_BENCH_LANDMARKS") != "demo" and (REAL / "landmarks.json").is_file() \
            and Path("/work/shared/data/plant3dimagereg").is_dir():
        return REAL / "rig.json", REAL / "landmarks.json", []
    return ctx.demo_folder() / "rig.json", None, [ctx.demo_folder() / "recording"]


def _lm_page(ctx: Context, fresh: bool = False):
    import plantreg_gui.gui.calibration.wizard  # noqa: F401  (imported by the main window before the
    import plantreg_gui.gui.registration.workspace  # noqa: F401  page is opened: not the page's cost)
    from plantreg_gui.gui.landmarks.page import LandmarkPage

    return ctx.widget("landmarks", LandmarkPage, fresh)


def _lm_open_setup(ctx: Context) -> None:
    _lm_files(ctx)  # the demo written, if used
    _lm_page(ctx, fresh=True)


def _lm_open_run(ctx: Context) -> None:
    rig, lms, recs = _lm_files(ctx)
    ctx.widgets["landmarks"].open(rig, lms, recs)


def _lm_opened(ctx: Context) -> bool:
    p = ctx.widgets["landmarks"]
    return p.session is not None and not p.is_busy()


def _lm_open(ctx: Context) -> None:
    _lm_page(ctx, fresh=True)
    _lm_open_run(ctx)
    ctx.wait(lambda: _lm_opened(ctx))


def _lm_refine_run(ctx: Context) -> None:
    """Refine, and Cancel once the refinement is under way (its levels, past the preparation)."""
    p = ctx.widgets["landmarks"]
    p.run_refine()
    ctx.wait(lambda: p.progress.value() >= 150 or not p.is_busy(include_overlay=False))
    p.cancel_button.click()


def _lm_refine_started(ctx: Context) -> None:
    """Setup of "Cancel" alone: refinement running (not measured)."""
    _lm_open(ctx)
    p = ctx.widgets["landmarks"]
    p.run_refine()
    ctx.wait(lambda: p.progress.value() >= 150 or not p.is_busy(include_overlay=False))


def _lm_idle(ctx: Context) -> bool:
    return not ctx.widgets["landmarks"].is_busy()


SCENARIOS: list[Scenario] = [
    Scenario("workspace: open rig + recording", _ws_open_setup, _ws_open_run, _ws_idle),
    Scenario("workspace: register (meshes built)", _ws_open, lambda ctx: _ws_register_run(ctx, "ir"), _ws_idle),
    Scenario("workspace: register another target", _ws_registered, lambda ctx: _ws_register_run(ctx, "rgb"),
             _ws_idle),
    Scenario("workspace: export (all outputs)", _ws_registered, _ws_export_run, _ws_idle),
    Scenario("workspace: switch views", _ws_registered, _ws_switch_views, lambda ctx: True),
    Scenario("workspace: resize to 2560 x 1440 and back", _ws_registered, _ws_resize, lambda ctx: True),
    Scenario("workspace: first show of the 3D tab", _ws_fresh_registered,
             lambda ctx: ctx.workspace().set_view("3d"), _ws_3d_shown),
    Scenario("workspace: Load demo (write, open, register)", _ws_load_demo_setup, _ws_load_demo_run, _ws_idle),
    Scenario("landmarks: open (recordings, overlay)", _lm_open_setup, _lm_open_run, _lm_opened),
    Scenario("landmarks: Refine then Cancel", _lm_open, _lm_refine_run, _lm_idle),
    Scenario("landmarks: Cancel of a running Refine", _lm_refine_started,
             lambda ctx: ctx.widgets["landmarks"].cancel_button.click(), _lm_idle),
]


class _LabelledProbe:
    """A StallProbe that remembers what the progress bars said before its longest gap."""

    def __init__(self, ctx: Context):
        from stall_probe import StallProbe

        self.probe = StallProbe()
        self.ctx = ctx
        self.label = ""
        self.worst_label = ""
        self.probe.timer.timeout.connect(self._tick)

    def _tick(self) -> None:
        if self.probe.gaps and self.probe.gaps[-1] >= self.probe.max_gap:
            self.worst_label = self.label
        self.label = self.ctx.progress_text()


class _Watchdog:
    """With ``--why``: a thread that, while the GUI thread's timer is late by more than 150 ms,
    samples the stacks of every thread (the GUI thread's shows work done there; a worker's shows
    who held the interpreter). Prints the most frequent innermost project frames."""

    def __init__(self, lp: "_LabelledProbe"):
        import collections
        import threading

        self.lp, self.samples = lp, collections.Counter()
        self.main = threading.main_thread().ident
        self._stop = threading.Event()
        self.thread = threading.Thread(target=self._loop, daemon=True)

    def _loop(self) -> None:
        import traceback

        while not self._stop.wait(0.05):
            if time.perf_counter() - self.lp.probe._last < 0.15:
                continue
            for ident, frame in sys._current_frames().items():
                if ident == self.thread.ident:
                    continue
                stack = traceback.extract_stack(frame)
                mine = [f for f in stack if "plantreg" in f.filename or "site-packages" not in f.filename]
                where = " < ".join(f"{Path(f.filename).name}:{f.lineno} {f.name}" for f in mine[-3:][::-1])
                top = f"{Path(stack[-1].filename).name}:{stack[-1].lineno} {stack[-1].name}"
                self.samples[("GUI" if ident == self.main else "worker", top, where)] += 1

    def __enter__(self):
        self.thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self.thread.join()
        for (who, top, where), n in self.samples.most_common(8):
            print(f"    {n * 50:5d} ms  {who:6s} {top}   [{where}]")


def startup_gap(app) -> float:
    """Seconds between the splash screen's hiding and the main window's showing, as
    ``plantreg-gui`` starts (``gui/startup.py``; 0 when the splash stays until the window is
    shown). Started a second time here, so the imports are warm: the window's construction is
    what is measured."""
    from PySide6.QtCore import QEvent, QObject
    from PySide6.QtWidgets import QSplashScreen

    from plantreg_gui import __version__
    from plantreg_gui.gui import startup
    from plantreg_gui.gui.main_window import MainWindow

    seen: dict[str, float] = {}

    class Filter(QObject):
        def eventFilter(self, obj, ev):  # noqa: N802
            if ev.type() == QEvent.Type.Hide and isinstance(obj, QSplashScreen):
                seen.setdefault("splash hidden", time.perf_counter())
            if ev.type() == QEvent.Type.Show and isinstance(obj, MainWindow):
                seen.setdefault("window shown", time.perf_counter())
            return False

    f = Filter()
    app.installEventFilter(f)
    try:
        if hasattr(startup, "open_main_window"):
            win = startup.open_main_window(app, __version__, (1500, 950))
        else:  # the start-up before the splash stayed: splash, then the window
            startup.preload_with_splash(app, __version__)
            win = MainWindow()
            win.resize(1500, 950)
            win.show()
        for _ in range(20):
            app.processEvents()
            time.sleep(0.02)
    finally:
        app.removeEventFilter(f)
    win.close()
    win.deleteLater()
    return max(0.0, seen.get("window shown", 0.0) - seen.get("splash hidden", float("inf")))


def run(names: list[str] | None = None, repeat: int = 1, why: bool = False) -> list[tuple[str, float, float, int, str]]:
    """Run the scenarios (all, or those whose name contains one of ``names``); returns rows
    (name, seconds, max gap seconds, gaps over 200 ms, label before the longest gap)."""
    from PySide6.QtWidgets import QApplication

    app = QApplication.instance() or QApplication(sys.argv[:1])
    from plantreg_gui.gui.startup import preload

    print(f"start-up: 3D stack imported in {preload():.2f} s (as plantreg-gui does, behind its splash)")
    if not names or any("start" in n for n in names):
        gap = startup_gap(app)
        print(f"start-up: {gap * 1000:.0f} ms with neither splash nor main window on screen "
              "(splash hidden -> main window shown)", flush=True)
    rows = []
    with tempfile.TemporaryDirectory(prefix="plantreg-bench-") as tmp:
        ctx = Context(app, Path(tmp))
        for sc in SCENARIOS:
            if names and not any(n.lower() in sc.name.lower() for n in names):
                continue
            for _ in range(repeat):
                sc.setup(ctx)
                ctx.wait(lambda: True)
                lp = _LabelledProbe(ctx)
                t0 = time.perf_counter()
                import contextlib

                from stall_probe import LoadControl

                with LoadControl() as control, lp.probe, (_Watchdog(lp) if why else contextlib.nullcontext()) as wd:
                    sc.run(ctx)
                    ctx.wait(lambda: sc.done(ctx))
                    ctx.wait(lambda: True)
                    lp.probe.stop()
                secs = time.perf_counter() - t0
                rows.append((sc.name, secs, lp.probe.max_gap, len(lp.probe.stalls(0.2)), lp.worst_label))
                print(f"{sc.name:<46} {secs:7.2f} s   max gap {lp.probe.max_gap * 1000:6.0f} ms   "
                      f"GUI CPU {lp.probe.max_cpu * 1000:4.0f} ms "
                      f"(in that gap {lp.probe.cpu_at_max_gap * 1000:4.0f})   "
                      f"gaps > 200 ms: {len(lp.probe.stalls(0.2)):2d}   control stretch {control.stretch:5.1f}x   "
                      f"before the longest: {lp.worst_label}", flush=True)
        for w in ctx.widgets.values():
            for name in ("shutdown", "close"):
                fn = getattr(w, name, None)
                if fn is not None:
                    fn()
    return rows


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--only", nargs="*", help="run only scenarios whose name contains one of these words")
    ap.add_argument("--repeat", type=int, default=1)
    ap.add_argument("--why", action="store_true", help="sample the threads' stacks during stalls")
    a = ap.parse_args(argv)
    print(f"GUI-thread stalls (20 ms timer), {os.cpu_count()} CPUs, load average "
          f"{' '.join(f'{x:.1f}' for x in os.getloadavg())}")
    run(a.only, a.repeat, a.why)
    return 0


if __name__ == "__main__":
    sys.exit(main())
