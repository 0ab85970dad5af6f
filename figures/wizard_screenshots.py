"""Screenshots of the calibration wizard's seven pages for docs/images (one run of the demo).

    PYTHONPATH=. xvfb-run -a .venv/bin/python figures/wizard_screenshots.py [--out docs/images]
        [--size 1500x950] [--pages 1-7] [--session FOLDER --name wizard-lepton-page]

Renders the demo (``plantreg demo``: calibration session and a plant recording), opens its
calibration session in the main window (1500 x 950), rejects one RGB view (so pages 3 and 4 show
how an excluded view looks), walks pages 1-7 and saves ``wizard-pageN.png``; on page 7 the ROI is
fitted to the demo plant's depth map, as a technician would do. ``--session`` opens that capture
session instead (nothing rejected, no ROI fitted) and names the files ``<name>N.png``; the
Lepton + ZED page of docs/calibration.md is a session built as ``tests/realcal.py``'s
``lepton_session`` builds it (symlinks in a temporary folder), ``--pages 4 --name
wizard-lepton-page``. Not part of the test run.
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
    ap.add_argument("--size", default="1500x950", help="window size WxH (default 1500x950)")
    ap.add_argument("--pages", default="1-7", help="pages to save: FIRST-LAST or a list 1,4,5 (default 1-7)")
    ap.add_argument("--session", type=Path, help="a capture session to show instead of the demo's")
    ap.add_argument("--name", default="wizard-page", help="file name before the page number (default wizard-page)")
    a = ap.parse_args(argv)
    width, height = (int(v) for v in a.size.lower().split("x"))
    first, _, last = a.pages.partition("-")
    pages = list(range(int(first), int(last) + 1)) if last else [int(v) for v in a.pages.split(",")]
    from PySide6.QtWidgets import QApplication

    from plantreg_gui.core.synthetic import write_demo
    from plantreg_gui.gui.main_window import MainWindow

    app = QApplication.instance() or QApplication(sys.argv[:1])
    demo = None
    if a.session is None:
        demo = Path(tempfile.mkdtemp(prefix="wizard-shots-")) / "demo"
        write_demo(demo)
    win = MainWindow()
    win.resize(width, height)
    win.show()
    win.tabs.setCurrentWidget(win.wizard)
    w = win.wizard
    w.open_session(a.session or demo / "calibration", resume=False)
    _wait(app, lambda: not w.is_busy())
    rgb = None
    if demo is not None:
        rgb = sorted(k for k, d in w.model.detections.items() if d.status == "found" and k[1] == "rgb")[-1]
        w.model.set_excluded_many({rgb}, True)
    for n in pages:
        w.go_to_page(n)
        _wait(app, lambda: not w.page_busy())
        if n == 3 and rgb is not None:
            w.pages[2].select("rgb", rgb[0])
        if n == 7 and demo is not None:
            w.pages[6].load_plant_depth(demo / "recording" / "recording.json")
        t = time.monotonic()
        _wait(app, lambda: time.monotonic() - t > 1.0)  # settle (3D view, timers)
        win.save_screenshot(a.out / f"{a.name}{n}.png")
    w.shutdown()
    win.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
