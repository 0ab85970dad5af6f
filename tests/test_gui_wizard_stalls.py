"""The wizard's GUI thread never freezes while it detects, calibrates and computes the error
tables (issue 11: 2.4 s, 1.9 s and 8-12 s stalls before).

Measured with :class:`~plantreg_gui.gui.stall_probe.StallProbe` (a 20 ms timer on the GUI
thread) while the wizard *resumes* the real OpenCV stereo session on page 7 -- detection,
calibration, error tables and the pages' redraws in one go.

Tolerance. The goal is no gap over 200 ms on an idle 2-core machine
(``benchmarks/bench_wizard_stalls.py`` measures it). Tests run on machines shared with other
work, where the operating system alone holds a process off the CPU for a second or more. So a
*control process* (same priority, no Qt, no GIL shared with us) runs a 20 ms sleep loop over the
same interval and records its own largest gap; the test allows ``max(1.0 s, 0.5 s + 2 x
control)``. A freeze of our making (work on the GUI thread, a worker holding the GIL: the
seconds-long stalls this guards against) shows in the probe but not in the control, and fails.
"""

from __future__ import annotations

import json
import shutil

import pytest

pytestmark = pytest.mark.gui


CONTROL = """
import os, sys, time
flag, last, worst = sys.argv[1], time.perf_counter(), 0.0
while not os.path.exists(flag):
    time.sleep(0.02)
    now = time.perf_counter()
    worst, last = max(worst, now - last), now
print(worst)
"""


class _Control:
    """The control process: the machine's own scheduling gaps over the measured interval."""

    def __init__(self, tmp_path) -> None:
        import subprocess
        import sys

        self.flag = tmp_path / "control.stop"
        self.proc = subprocess.Popen([sys.executable, "-c", CONTROL, str(self.flag)], stdout=subprocess.PIPE,
                                     text=True)

    def stop(self) -> float:
        self.flag.write_text("stop")
        out, _ = self.proc.communicate(timeout=60)
        return float(out.strip())


def test_resuming_a_session_on_page_7_never_freezes_the_gui(qtbot, shared_data, tmp_path):
    from plantreg_gui.gui.calibration.wizard import CalibrationWizard
    from plantreg_gui.gui.stall_probe import StallProbe

    folder = tmp_path / "stereo"
    shutil.copytree(shared_data / "opencv-stereo", folder)
    meta = json.loads((folder / "session.json").read_text())
    meta.setdefault("review", {})["wizard_page"] = 7  # left on page 7 last time
    (folder / "session.json").write_text(json.dumps(meta))

    w = CalibrationWizard()
    qtbot.addWidget(w)
    w.resize(1400, 900)
    w.show()
    qtbot.waitExposed(w)
    try:
        control = _Control(tmp_path)
        qtbot.wait(300)  # the control process is running
        with StallProbe() as probe:
            assert w.open_session(folder)
            assert w.page == 7 and w.is_busy()
            qtbot.waitUntil(lambda: not w.is_busy(), timeout=600_000)
            # the pages drawn with the results; not page 5, whose 3D view's first OpenGL render (shader
            # compilation; 0.2-2 s with software OpenGL) is the one stall left, see docs/wizard.md
            for page in (4, 6, 3, 2, 7):
                w.go_to_page(page)
                qtbot.wait(100)
        base = control.stop()
        allowed = max(1.0, 0.5 + 2 * base)
        assert w.model.calibration_ready() and w.model.report_ready(), w.last_error
        assert probe.ticks > 20
        assert probe.max_gap < allowed, (
            f"GUI thread stalled {probe.max_gap * 1000:.0f} ms (allowed {allowed * 1000:.0f} ms, control "
            f"{base * 1000:.0f} ms); gaps over 200 ms: {[round(g * 1000) for g in probe.stalls(0.2)]}")
    finally:
        w.shutdown()
        w.close()
