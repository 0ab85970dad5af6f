"""Screenshots of the calibration wizard's seven pages for docs/images (one run of the demo).

    PYTHONPATH=. xvfb-run -a .venv/bin/python figures/wizard_screenshots.py [--out docs/images]

Renders the demo (``plantreg demo``: calibration session and a plant recording), opens its
calibration session in the main window (1500 x 950), rejects one RGB view (so pages 3 and 4 show
how an excluded view looks), walks pages 1-7 and saves ``wizard-pageN.png``; on page 7 the ROI is
fitted to the demo plant's depth map, as a technician would do. Not part of the test run.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path


def _wait(app, cond, timeout_s: float = 1800) -> None:
    t_end = time.monotonic() + timeout_s
    while not cond():
        app.processEvents()
        time.sleep(0.02)
        if time.monotonic() > t_end:
            raise TimeoutError


def main(argv=None) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", type=Path, default=Path(__file__).resolve().parents[1] / "docs" / "images")
    a = ap.parse_args(argv)
    from PySide6.QtWidgets import QApplication

    from plantreg_gui.core.synthetic import write_demo
    from plantreg_gui.gui.main_window import MainWindow

    app = QApplication.instance() or QApplication(sys.argv[:1])
    demo = Path(tempfile.mkdtemp(prefix="wizard-shots-")) / "demo"
    write_demo(demo)
    win = MainWindow()
    win.resize(1500, 950)
    win.show()
    win.tabs.setCurrentWidget(win.wizard)
    w = win.wizard
    w.open_session(demo / "calibration", resume=False)
    _wait(app, lambda: not w.is_busy())
    rgb = sorted(k for k, d in w.model.detections.items() if d.status == "found" and k[1] == "rgb")[-1]
    w.model.set_excluded_many({rgb}, True)
    for n in range(1, 8):
        w.go_to_page(n)
        _wait(app, lambda: not w.page_busy())
        if n == 3:
            w.pages[2].select("rgb", rgb[0])
        if n == 7:
            w.pages[6].load_plant_depth(demo / "recording" / "recording.json")
        t = time.monotonic()
        _wait(app, lambda: time.monotonic() - t > 1.0)  # settle (3D view, timers)
        win.save_screenshot(a.out / f"wizard-page{n}.png")
    w.shutdown()
    win.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
