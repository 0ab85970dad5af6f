"""The wizard's GUI thread never freezes while it detects, calibrates and computes the error
tables (issue 11: 2.4 s, 1.9 s and 8-12 s stalls before).

Measured with :class:`~stall_probe.StallProbe` (a 20 ms timer on the GUI
thread) while the wizard *resumes* the real OpenCV stereo session on page 7 -- detection,
calibration, error tables and the pages' redraws in one go.

Tolerance. The goal is no gap over 200 ms on an idle 2-core machine
(``benchmarks/bench_wizard_stalls.py`` measures it). Tests run on machines shared with other
work, where a process that wants the CPU waits for it (at a load of 20 on 2 cores, 50 ms of
painting takes half a second). So a control process (:class:`stall_probe.LoadControl`: same
priority, no Qt, no GIL shared with us, 20 ms of CPU work and 20 ms of sleep like an event loop)
runs over the same interval; the test allows 1 s widened by the stretch it saw. On an idle machine
that is about 1 s: the freezes this guards against (seconds of work on the GUI thread or of a
worker holding the GIL) fail it; on a busy machine the test is correspondingly weaker.
"""

from __future__ import annotations

import json
import shutil

import pytest

pytestmark = pytest.mark.gui


def test_resuming_a_session_on_page_7_never_freezes_the_gui(qtbot, shared_data, tmp_path):
    from plantreg_gui.gui.calibration.wizard import CalibrationWizard
    from stall_probe import LoadControl, StallProbe

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
        with LoadControl() as control, StallProbe() as probe:
            assert w.open_session(folder)
            assert w.page == 7 and w.is_busy()
            qtbot.waitUntil(lambda: not w.is_busy(), timeout=600_000)
            # the pages drawn with the results, page 5's 3D view too (drawn in stages: its first
            # OpenGL frames with software GL no longer stall, see docs/wizard.md)
            for page in (4, 5, 6, 3, 2, 7):
                w.go_to_page(page)
                if page == 5:
                    view = w.pages[4].view3d
                    qtbot.waitUntil(lambda: view.n_frusta > 0 and not view.building or view.error is not None,
                                    timeout=30000)
                qtbot.wait(100)
        allowed = control.allowed(1.0)
        assert w.model.calibration_ready() and w.model.report_ready(), w.last_error
        assert probe.ticks > 20
        assert probe.max_gap < allowed, (
            f"GUI thread stalled {probe.max_gap * 1000:.0f} ms (allowed {allowed * 1000:.0f} ms, control's "
            f"stretch {control.stretch:.2f}); gaps over 200 ms: {[round(g * 1000) for g in probe.stalls(0.2)]}")
    finally:
        w.shutdown()
        w.close()
