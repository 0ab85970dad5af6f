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


#: Window sides ``--size`` accepts, pixels: smaller cannot show a page (0x0 never drew, so a
#: ``--screenshot`` waited for ever); larger than any screen or Xvfb framebuffer.
MIN_SIDE, MAX_SIDE = 200, 16384
#: Wizard pages (``--page``).
PAGES = 7


def window_size(text: str) -> tuple[int, int]:
    """``--size WxH`` -> (W, H), each a whole number from :data:`MIN_SIDE` to :data:`MAX_SIDE`."""
    try:
        w, h = (int(x) for x in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be WIDTHxHEIGHT, e.g. 1500x950, got '{text}'") from None
    if not (MIN_SIDE <= w <= MAX_SIDE and MIN_SIDE <= h <= MAX_SIDE):
        raise argparse.ArgumentTypeError(f"width and height must be {MIN_SIDE} to {MAX_SIDE} pixels, got '{text}'")
    return w, h


def wizard_page(text: str) -> int:
    try:
        n = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not a whole number") from None
    if not 1 <= n <= PAGES:
        raise argparse.ArgumentTypeError(f"must be a page from 1 to {PAGES}, got '{text}'")
    return n


def build_parser() -> argparse.ArgumentParser:
    from ..cli import nonempty_path, positive_float

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
    g.add_argument("--page", type=wizard_page, help="wizard page to show (1-7); earlier pages' work is run first")
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
    g.add_argument("--screenshot", type=nonempty_path, help="save a PNG of the window once the work is done, then exit")
    g.add_argument("--size", type=window_size, default=(1500, 950), metavar="WxH",
                   help=f"window size WxH, {MIN_SIDE} to {MAX_SIDE} pixels a side (default 1500x950)")
    g.add_argument("--timeout", type=positive_float, default=300.0,
                   help="seconds to wait for work before a screenshot (a positive number)")
    return p


def _screenshot_problem(args: argparse.Namespace) -> str | None:
    """Why ``--screenshot`` cannot be written (None: it can): the shared output check
    (``core/io/paths.py``), with the files the options open as inputs (a screenshot over the rig
    replaced it with a PNG; over a FIFO it waited for ever; into a read-only folder it said
    "saved")."""
    from ..core.errors import PlantregError
    from ..core.io.paths import check_output_location

    try:
        inputs = [p for p in (args.rig, args.recording, args.session, args.landmarks) if p is not None]
        if args.recording is not None:
            from ..core.data.recording import recording_inputs

            inputs += recording_inputs(args.recording)
        check_output_location(args.screenshot, "screenshot", overwrite=True, inputs=inputs)
    except PlantregError as e:
        return str(e)
    return None


def main(argv: list[str] | None = None) -> int:
    import multiprocessing

    multiprocessing.freeze_support()  # the wizard's worker process (core/jobs/process_job.py) in a frozen app
    args = build_parser().parse_args(argv)
    if args.install_desktop or args.uninstall_desktop:  # no Qt needed
        from ..desktop import main as desktop_main

        return desktop_main("install" if args.install_desktop else "uninstall")
    w, h = args.size
    if args.screenshot is not None:  # the output check every command uses, before any window
        problem = _screenshot_problem(args)
        if problem:
            print(f"plantreg-gui: error: {problem}", file=sys.stderr)
            return 1
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
