"""The landmark page on the real grapevine with the issue-23 newcomer click added (u = 206.5, just
past the left leaf's margin notch: the depth camera sees the ground there), as docs/fit-rig.md
shows it; prints how long the depth checks take.

    xvfb-run -a -s "-screen 0 1800x1100x24" .venv/bin/python benchmarks/bench_landmark_depth_page.py \\
        [--camera hyperspectral] [--no-snap-depth] [--out docs/images/landmarks-page.png]

Needs the Plant3DImageReg data set beside the project (resources/plant3dimagereg/README.md).
Writes only the screenshot (default /tmp/landmarks-page.png)."""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
REAL = ROOT / "resources" / "plant3dimagereg"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--camera", default="hyperspectral")
    ap.add_argument("--no-snap-depth", action="store_true")
    ap.add_argument("--out", default="/tmp/landmarks-page.png")
    args = ap.parse_args()

    from PySide6.QtWidgets import QApplication

    from plantreg_gui.core.progress import Reporter
    from plantreg_gui.core.rigfit.rigfit import check_landmark_depth
    from plantreg_gui.gui.landmarks.page import LandmarkPage, read_session

    app = QApplication.instance() or QApplication([])
    s, shown = read_session(REAL / "rig.json", REAL / "landmarks.json", [], Reporter())
    s.set_camera(args.camera)
    s.add_point([206.5, 235.0], {"hyperspectral": [250.16, 443.1]}, "newcomer's click at the margin notch (issue 23)")
    s.set_snap_depth(not args.no_snap_depth)
    n = sum(len(s.landmarks.recordings[k]) for k in s.recording_keys)
    t = time.perf_counter()
    for k in s.recording_keys:
        for lm in s.landmarks.recordings[k]:
            check_landmark_depth(s.depth_m(k), lm.depth_uv, s.rig.ground_z, s.snap_depth)
    t_checks = time.perf_counter() - t
    s.table()  # reads the new point's check once
    t = time.perf_counter()
    s.table()
    t_table = time.perf_counter() - t
    print(f"depth checks of all {n} landmarks: {1000 * t_checks:.0f} ms; the current recording's table "
          f"({len(s.points)} points, checks kept): {1000 * t_table:.1f} ms; load average {os.getloadavg()[0]:.1f}")

    page = LandmarkPage()
    page.resize(1500, 950)
    page.show()
    page.set_session(s, shown)
    s.select(len(s.points) - 1)
    deadline = time.time() + 600
    while page.is_busy() and time.time() < deadline:
        app.processEvents()
        time.sleep(0.05)
    for _ in range(20):
        app.processEvents()
        time.sleep(0.05)
    page.grab().save(args.out)
    print("wrote", args.out)
    gaps = []
    for _ in range(4):  # the switch and back: the page repaints its table, markers and hint
        t = time.perf_counter()
        page.snap_depth.click()
        app.processEvents()
        gaps.append(time.perf_counter() - t)
    print(f"snap switch, click to repainted: {', '.join(f'{1000 * g:.0f}' for g in gaps)} ms; "
          f"load average {os.getloadavg()[0]:.1f}")
    for r in s.table():
        d = r["depth"]
        res = "-" if r["residual_px"] is None else f"{r['residual_px']:.2f} px"
        print(f"  #{r['index']:<3} {res:>9}  {d.status:<9} {d.z_m:.3f} m  {r['note'][:60]}")
    page.shutdown()


if __name__ == "__main__":
    main()
