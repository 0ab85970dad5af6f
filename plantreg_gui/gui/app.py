"""``plantreg-gui``: the desktop application.

Start options open a view straight away; ``--screenshot PATH`` waits until the opened view has
finished its work, saves a PNG of the window and exits (for docs and for checking by eye).
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from .. import __version__, prefer_one_blas_thread

prefer_one_blas_thread()  # before numpy is first imported (the views and the core import it)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="plantreg-gui", description="plantreg desktop application")
    p.add_argument("--version", action="version", version=f"plantreg {__version__}")
    g = p.add_argument_group("registration workspace")
    g.add_argument("--demo", action="store_true", help="open the built-in demo rig and recording and register it")
    g.add_argument("--rig", type=Path, help="rig file (plantreg.rig JSON)")
    g.add_argument("--recording", type=Path, help="recording folder (with recording.json)")
    g.add_argument("--target", help="target camera to register to")
    from .registration.views import view_keys

    g.add_argument("--view", help=f"workspace view to show: {', '.join(view_keys())}")
    g = p.add_argument_group("calibration wizard")
    g.add_argument("--calibrate-demo", action="store_true", help="open the synthetic calibration session of the demo")
    g.add_argument("--session", type=Path, help="open a capture session folder in the calibration wizard")
    g.add_argument("--page", type=int, help="wizard page to show (1-7); earlier pages' work is run first")
    g = p.add_argument_group("landmark page")
    g.add_argument("--landmarks", type=Path, help="open the landmark page on this landmarks file (with --rig; "
                   "--recording adds a recording folder)")
    g = p.add_argument_group("desktop integration (Linux)")
    g = g.add_mutually_exclusive_group()
    g.add_argument("--install-desktop", action="store_true",
                   help="add plantreg to your applications menu (a desktop entry running this installed "
                        "plantreg-gui, and its icon, under $XDG_DATA_HOME or ~/.local/share), then exit")
    g.add_argument("--uninstall-desktop", action="store_true",
                   help="remove what --install-desktop added, then exit")
    g = p.add_argument_group("automation")
    g.add_argument("--screenshot", type=Path, help="save a PNG of the window once the work is done, then exit")
    g.add_argument("--size", default="1500x950", help="window size WxH (default 1500x950)")
    g.add_argument("--timeout", type=float, default=300.0, help="seconds to wait for work before a screenshot")
    return p


def main(argv: list[str] | None = None) -> int:
    import multiprocessing

    multiprocessing.freeze_support()  # the wizard's worker process (core/jobs/process_job.py) in a frozen app
    args = build_parser().parse_args(argv)
    if args.install_desktop or args.uninstall_desktop:  # no Qt needed
        from ..desktop import main as desktop_main

        return desktop_main("install" if args.install_desktop else "uninstall")
    try:
        w, h = (int(x) for x in args.size.lower().split("x"))
    except ValueError:
        print(f"plantreg-gui: error: --size must be WIDTHxHEIGHT, got '{args.size}'", file=sys.stderr)
        return 2
    os.environ.setdefault("QT_API", "pyside6")
    from PySide6.QtWidgets import QApplication

    app = QApplication.instance() or QApplication(sys.argv[:1])
    app.setApplicationName("plantreg")
    app.setOrganizationName("plantreg")
    app.setApplicationVersion(__version__)
    app.setDesktopFileName("plantreg-gui")  # Wayland's app id: the installed entry's icon and name
    from .startup import open_main_window

    win = open_main_window(app, __version__, (w, h))  # the 3D stack loaded before any window takes input
    try:
        win.apply_start_options(args)
    except Exception as e:  # user mistakes reach the user as text, not a traceback
        from ..core.errors import PlantregError

        if not isinstance(e, PlantregError):
            raise
        print(f"plantreg-gui: error: {e}", file=sys.stderr)
        if args.screenshot:
            return 1
        from .workers import show_error

        show_error(win, "Cannot open", str(e))
    if args.screenshot:
        win.screenshot_when_idle(args.screenshot, args.timeout, done=app.exit)
    rc = app.exec()
    # the views' teardown (workers, 3D plotters) also when the loop ended without closing the
    # window (--screenshot, app.exit): else pyvistaqt closes a plotter whose timer Qt already deleted
    win.close()
    return rc


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
