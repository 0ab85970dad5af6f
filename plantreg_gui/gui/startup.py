"""What the application loads before its window appears.

VTK (through pyvista/pyvistaqt) is slow to import, and most of that time is spent in C code
that holds the GIL (extension-module initialisation, PySide6's ``import *`` in qtpy). Importing it
on a worker thread therefore still froze the GUI thread for visible moments, in the middle of
the user's first registration. It is imported here instead, once, behind a splash screen, before
any window can take input.
"""

from __future__ import annotations

import importlib
import time

#: Slow modules every session needs sooner or later (the 3D views). The three VTK modules are
#: what the first pyvistaqt plotter imported on the GUI thread (figures: benchmarks/bench_gui_stalls.py).
HEAVY_MODULES: tuple[str, ...] = ("pyvista", "pyvistaqt", "vtkmodules.vtkInteractionWidgets",
                                  "vtkmodules.vtkViewsContext2D", "vtkmodules.vtkViewsCore")


def preload(modules: tuple[str, ...] = HEAVY_MODULES, open3d: bool = True) -> float:
    """Import ``modules`` on the calling (GUI) thread, and with ``open3d`` Open3D's compiled core
    (``core/geometry/o3d_core.py``); returns the seconds it took. A module that fails to import is left for
    the view that needs it to report.

    Why Open3D: its core (the ray caster of every registration, and of the landmark page's
    overlay) is slow to initialise, mostly in C holding the GIL; first loaded on a worker, it
    froze the GUI thread during the landmark page's first open (benchmarks/bench_gui_stalls.py)."""
    t0 = time.perf_counter()
    for name in modules:
        try:
            importlib.import_module(name)
        except Exception:  # noqa: BLE001 - reported by the view that needs it
            pass
    if open3d:
        try:
            from ..core.geometry.o3d_core import open3d_core

            open3d_core()
        except Exception:  # noqa: BLE001 - reported by the registration that needs it
            pass
    return time.perf_counter() - t0


def show_splash(app, version: str):
    """A small splash screen (nothing to click), shown at once; returns it."""
    from PySide6.QtCore import Qt
    from PySide6.QtGui import QColor, QFont, QPainter, QPixmap
    from PySide6.QtWidgets import QSplashScreen

    pix = QPixmap(440, 120)
    pix.fill(QColor("#20262e"))
    p = QPainter(pix)
    p.setPen(QColor("#e8eef4"))
    f = QFont()
    f.setPointSize(18)
    f.setBold(True)
    p.setFont(f)
    p.drawText(24, 52, "plantreg")
    f.setPointSize(10)
    f.setBold(False)
    p.setFont(f)
    p.drawText(26, 78, f"version {version} — multimodal 3D registration")
    p.end()
    splash = QSplashScreen(pix)
    splash.show()
    splash_message(splash, "Loading the 3D viewer and the ray caster…")
    app.processEvents()
    return splash


def splash_message(splash, text: str) -> None:
    from PySide6.QtCore import Qt
    from PySide6.QtGui import QColor

    splash.showMessage(text, Qt.AlignmentFlag.AlignBottom | Qt.AlignmentFlag.AlignLeft, QColor("#9fb3c8"))


def open_main_window(app, version: str, size: tuple[int, int], window_class=None):
    """The start-up: :func:`preload` behind a splash screen, then the main window built and
    shown while the splash still stands, which goes away only once the window is on screen (the
    window's construction was a second of nothing on screen between splash and window).
    ``window_class``: the window to build (default :class:`~.main_window.MainWindow`)."""
    splash = show_splash(app, version)
    preload()
    splash_message(splash, "Opening the window…")
    app.processEvents()
    if window_class is None:
        from .main_window import MainWindow as window_class
    win = window_class()
    win.resize(*size)
    win.show()
    splash.finish(win)  # closes the splash once the window is exposed
    splash.deleteLater()
    return win
