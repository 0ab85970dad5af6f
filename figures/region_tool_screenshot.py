"""Screenshot of the workspace's region tool (README / docs/workspace.md): the demo registered
into ir, a rectangle over the plant, the thermal statistics in the side panel.

    xvfb-run -a python figures/region_tool_screenshot.py OUT.png [--source thermal] [--limits 20 24]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("out", type=Path)
    ap.add_argument("--source", default="thermal")
    ap.add_argument("--limits", type=float, nargs=2, default=None, help="absolute thermal limits, °C")
    ap.add_argument("--size", default="1500x950")
    args = ap.parse_args()
    from PySide6.QtCore import QTimer
    from PySide6.QtWidgets import QApplication

    from plantreg_gui.gui.main_window import MainWindow

    app = QApplication.instance() or QApplication(sys.argv[:1])
    app.setOrganizationName("plantreg-screenshots")  # not the user's remembered settings
    from plantreg_gui.gui.startup import preload

    preload()  # as plantreg-gui does: the 3D stack before the window
    win = MainWindow()
    w, h = (int(x) for x in args.size.split("x"))
    win.resize(w, h)
    win.show()
    ws = win.workspace

    def registered(_result) -> None:
        s = ws.session
        ws.region_panel.set_tool("rect")
        s.set_masks_source(args.source)
        x0, y0, x1, y1 = s.home
        cx, cy = (x0 + x1) / 2, (y0 + y1) / 2
        s.set_region("rect", (x0 + 0.05 * (x1 - x0), cy - 0.35 * (y1 - y0), cx + 0.3 * (x1 - x0), cy))
        if args.limits:
            st = s.settings_for("thermal").with_(limits=tuple(args.limits))
            ws.controls.apply("thermal", st)
            ws.controls.layer.setCurrentText("thermal")
        QTimer.singleShot(1500, shoot)

    def shoot() -> None:
        win.save_screenshot(args.out)
        print(ws.session.region_csv()[:400])
        app.exit(0)

    ws.registered.connect(registered)
    ws.load_demo(target="ir")
    rc = app.exec()
    ws.shutdown()
    return rc


if __name__ == "__main__":
    sys.exit(main())
