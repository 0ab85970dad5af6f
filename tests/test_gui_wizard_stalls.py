"""The wizard's GUI thread never freezes while it detects, calibrates and computes the error
tables (issue 11: 2.4 s, 1.9 s and 8-12 s stalls before).

Measured with :class:`~plantreg_gui.gui.stall_probe.StallProbe` (a 20 ms timer on the GUI
thread) while the wizard *resumes* the real OpenCV stereo session on page 7 -- detection,
calibration, error tables and the pages' redraws in one go.

Tolerance. The goal is no gap over 200 ms on an idle 2-core machine
(``benchmarks/bench_wizard_stalls.py`` measures it). Tests run on machines shared with other
work, where the operating system alone can hold the GUI thread off the CPU for a while, so the
test first measures the largest gap of the *idle* event loop for 1.5 s (``baseline``) and allows
``max(1.0 s, 5 x baseline)``. That still fails on the freezes this guards against (seconds long,
from work holding the GIL or running on the GUI thread), which are independent of the load.
"""

from __future__ import annotations

import json
import shutil

import pytest

pytestmark = pytest.mark.gui


def _baseline(qtbot) -> float:
    from plantreg_gui.gui.stall_probe import StallProbe

    with StallProbe() as probe:
        qtbot.wait(1500)
    return probe.max_gap


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
        base = _baseline(qtbot)
        allowed = max(1.0, 5 * base)
        with StallProbe() as probe:
            assert w.open_session(folder)
            assert w.page == 7 and w.is_busy()
            qtbot.waitUntil(lambda: not w.is_busy(), timeout=600_000)
            # the pages drawn with the results; not page 5, whose 3D view's first OpenGL render (shader
            # compilation; 0.2-2 s with software OpenGL) is the one stall left, see docs/wizard.md
            for page in (4, 6, 3, 2, 7):
                w.go_to_page(page)
                qtbot.wait(100)
        assert w.model.calibration_ready() and w.model.report_ready(), w.last_error
        assert probe.ticks > 20
        assert probe.max_gap < allowed, (
            f"GUI thread stalled {probe.max_gap * 1000:.0f} ms (allowed {allowed * 1000:.0f} ms, idle baseline "
            f"{base * 1000:.0f} ms); gaps over 200 ms: {[round(g * 1000) for g in probe.stalls(0.2)]}")
    finally:
        w.shutdown()
        w.close()
