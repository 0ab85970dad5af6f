"""The landmark page under Xvfb (pytest-qt): click pairs, drag, undo, fit, overlay, nudge, refine,
save -- against the demo's known truth, with the GUI thread watched by StallProbe.

Stall tolerance: the target is no GUI-thread gap over 200 ms; on the shared 2-core test machine
(other jobs running) a gap up to 0.5 s is accepted, as in tests/test_gui_workspace.py. The
measured maximum is printed.
"""

import json
import re

import numpy as np
import pytest
from PySide6.QtCore import QPointF, Qt

from plantreg_gui.models.landmarks import LandmarkSession
from plantreg_gui.core.data.landmarks import LandmarkSet
from plantreg_gui.core.data.recording import Recording
from plantreg_gui.core.camera.rig import Rig
from plantreg_gui.core.rigfit.rigfit import RecordingLandmarks, evaluate_landmarks
from plantreg_gui.core.synthetic import make_plant_scene
from plantreg_gui.core.synthetic.landmarks import perturb_rig, synthetic_landmarks

CAM = "thermal"
ALLOWED_GAP_S = 0.5  # on an idle machine; widened by a control measured alongside (stall_probe.LoadControl)


@pytest.fixture(scope="module")
def demo(demo_dir):
    rig = Rig.load(demo_dir / "rig.json")
    rec = Recording.load(demo_dir / "recording", rig)
    scene = make_plant_scene(0)  # write_demo's default seed
    return rig, rec, scene


def unseen_px(true_rig, fitted, scene, rec):
    lms = synthetic_landmarks(true_rig, scene, 12, 0.0, np.random.default_rng(77), sources=[CAM])
    rows, _ = evaluate_landmarks(fitted, [RecordingLandmarks("u", rec.depth_m(true_rig.depth_scale), lms)], [CAM])
    return float(np.median([d["residual_px"] for d in rows]))


def click(qtbot, view, uv):
    """Left click at image pixel ``uv`` (pixel centres at integers); returns where it landed."""
    p = view.mapFromScene(QPointF(uv[0] + 0.5, uv[1] + 0.5))
    qtbot.mouseClick(view.viewport(), Qt.MouseButton.LeftButton, pos=p)
    return p


@pytest.fixture
def page(qtbot, demo, tmp_path):
    from plantreg_gui.gui.landmarks.page import LandmarkPage

    rig, rec, scene = demo
    start = perturb_rig(rig, np.random.default_rng(4), 3.0, 0.03, 0.0, cameras=[CAM])
    lms = LandmarkSet(base=tmp_path, path=tmp_path / "landmarks.json")
    s = LandmarkSession(start, lms, {"plant": rec})
    s.set_camera(CAM)
    p = LandmarkPage()
    qtbot.addWidget(p)
    p.resize(1500, 900)
    p.show()
    qtbot.waitExposed(p)
    p.set_session(s)
    qtbot.waitUntil(lambda: not p.is_busy(), timeout=300_000)
    yield p
    p.shutdown()


def test_click_pairs_fit_overlay_nudge_save(qtbot, page, demo, tmp_path):
    from stall_probe import LoadControl, StallProbe

    rig, rec, scene = demo
    s = page.session
    before = unseen_px(rig, s.rig, scene, rec)
    truth = synthetic_landmarks(rig, scene, 12, 0.0, np.random.default_rng(5), sources=[CAM])
    for lm in truth:  # clicks at the fitted zoom land within one screen pixel (about 1.3 image px)
        click(qtbot, page.left, lm.depth_uv)
        assert s.pending is not None and np.allclose(s.pending, lm.depth_uv, atol=1.0)
        click(qtbot, page.right, lm.cameras[CAM])
        assert s.pending is None
    assert len(s.points) == 12 and page.table.rowCount() == 12
    # a click in the camera view without a depth click first adds nothing
    click(qtbot, page.right, truth[0].cameras[CAM])
    assert len(s.points) == 12

    # drag point 0 in the camera view to the exact (sub-pixel) truth, one undo step
    s.select(0)
    target = truth[0].cameras[CAM] + np.array([0.3, -0.2])
    page._drag_start(0, None)
    page._drag(0, None, *target, True)
    assert np.allclose(s.points[0].cameras[CAM], target)
    page.undo_button.click()
    assert not np.allclose(s.points[0].cameras[CAM], target)

    # delete and undo
    s.select(3)
    page.delete_button.click()
    assert len(s.points) == 11
    page.undo_button.click()
    assert len(s.points) == 12

    with LoadControl() as control, StallProbe() as probe:
        with qtbot.waitSignal(page.fit_done, timeout=120_000):
            page.fit_button.click()
        with qtbot.waitSignal(page.overlay_ready, timeout=300_000):
            pass
    after = unseen_px(rig, s.rig, scene, rec)
    print(f"fit: unseen residual {before:.1f} -> {after:.2f} px; max GUI gap {probe.max_gap * 1000:.0f} ms "
          f"(control's stretch {control.stretch:.2f})")
    assert before > 10.0 and after < 1.0  # click quantisation averages out over 12 points
    assert probe.ticks > 5 and probe.max_gap < control.allowed(ALLOWED_GAP_S), probe.stalls(0.2)
    assert page.overlay is not None and page.overlay.mapped.mean() > 0.05
    assert "thermal" in page.report_text.toPlainText()
    # every point's residual is drawn next to it and the table is worst first
    res = [float(page.table.item(r, 1).text()) for r in range(page.table.rowCount())]
    # (a depth pixel at a leaf edge can take its depth from the surface behind: such a point is
    # flagged as an outlier by the robust fit and tops the table, the others stay near zero)
    assert res == sorted(res, reverse=True) and float(np.median(res)) < 1.0
    assert all(":" in m.label for m in page.right.markers)

    # nudge with keys: W tilts 0.2 degrees, the overlay is redone on a worker
    page.left.setFocus()
    t0 = s.rig.camera(CAM).R_cam_rig.copy()
    with LoadControl() as control, StallProbe() as probe:
        qtbot.keyClick(page.left, Qt.Key.Key_W)
        qtbot.keyClick(page.left, Qt.Key.Key_W, Qt.KeyboardModifier.ShiftModifier)
        with qtbot.waitSignal(page.overlay_ready, timeout=300_000):
            pass
    dR = s.rig.camera(CAM).R_cam_rig @ t0.T
    assert np.degrees(np.arccos((np.trace(dR) - 1) / 2)) == pytest.approx(1.2, abs=1e-6)
    assert probe.max_gap < control.allowed(ALLOWED_GAP_S), probe.stalls(0.2)
    assert unseen_px(rig, s.rig, scene, rec) > 2.0
    with qtbot.waitSignal(page.fit_done, timeout=120_000):
        page.fit_button.click()
    assert unseen_px(rig, s.rig, scene, rec) < 1.0

    # save both
    page.save_lm_button.click()
    back = LandmarkSet.load(tmp_path / "landmarks.json")
    assert back.count() == 12
    s.save_rig(tmp_path / "rig.json")
    d = json.loads((tmp_path / "rig.json").read_text())
    assert d["calibration"]["landmarks_used"] == 12
    for mode in ("checkerboard", "flicker", "blend"):
        page.mode_combo.setCurrentText(mode)
        assert page.over.array is not None


def _refine_available() -> bool:
    try:
        import plantreg_gui.core.rigfit.refine  # noqa: F401
    except ImportError:
        return False
    return True


def test_refine_runs_on_a_worker_with_progress_and_cancel(qtbot, page, demo):
    """The Refine button: on a worker, progress shown, cancel honoured, result applied (undoable).

    With core/rigfit/refine.py present the real refinement runs on the demo's textured images; without it
    (it lands from another branch) the page must say so instead of failing."""
    rig, rec, scene = demo
    s = page.session
    if not _refine_available():
        from plantreg_gui.core.errors import InputError

        with pytest.raises(InputError, match="not available"):
            s.refine_job()
        pytest.xfail("core/rigfit/refine.py (issue 8 part 2) is not merged into this branch yet")
    from plantreg_gui.core.rigfit.refine import RefineParams

    before = unseen_px(rig, s.rig, scene, rec)
    # cancel: the worker stops at its next progress call and the rig stays as it was
    rig0 = s.rig.to_dict()
    page.run_refine()
    assert page.is_busy(include_overlay=False) and page.cancel_button.isEnabled()
    with qtbot.waitSignal(page._refine_worker.cancelled, timeout=120_000):
        page.cancel_button.click()
    assert s.rig.to_dict() == rig0
    # a full run (reduced levels: the demo start is 3 degrees off)
    s.refine_fn = None
    job = s.refine_job(params=RefineParams(levels_deg=(1.6, 0.4, 0.0), max_points=2000, min_points=1000))
    from plantreg_gui.gui.workers import Worker

    seen = []
    w = Worker(job)
    w.progress.connect(lambda f, m: seen.append(f))
    with qtbot.waitSignal(w.finished, timeout=300_000) as blocker:
        w.start()
    page._refine_finished(blocker.args[0])
    after = unseen_px(rig, s.rig, scene, rec)
    print(f"refine: unseen residual {before:.1f} -> {after:.2f} px")
    assert seen and after < before / 3
    s.undo()
    assert s.rig.to_dict() == rig0


def _add_truth_points(s, rig, scene, n=12, seed=5):
    for lm in synthetic_landmarks(rig, scene, n, 0.0, np.random.default_rng(seed), sources=[CAM]):
        s.add_point(lm.depth_uv, {CAM: lm.cameras[CAM]})


def _median_residual(rig, s):
    rows, _ = evaluate_landmarks(rig, [RecordingLandmarks("plant", s.depth_m("plant"), s.points)], [CAM])
    return float(np.median([d["residual_px"] for d in rows]))


def test_report_follows_the_rig_through_undo_and_nudge(qtbot, page, demo, tmp_path):
    """The report pane and the saved rig's provenance describe the rig they sit beside: undoing a
    fit takes its report away with it, and after a nudge the residuals shown and saved are the
    nudged rig's (before, both kept the fit's figures: a fitted-looking provenance on an unfitted
    or hand-moved rig)."""
    rig, rec, scene = demo
    s = page.session
    _add_truth_points(s, rig, scene)
    with qtbot.waitSignal(page.fit_done, timeout=120_000):
        page.fit_button.click()
    assert "landmark fit" in page.report_text.toPlainText()
    page.undo_button.click()  # back to the unfitted start rig
    text = page.report_text.toPlainText()
    assert "landmark fit" not in text and "not fitted yet" in text
    s.save_rig(tmp_path / "undone.json")
    assert "calibration" not in json.loads((tmp_path / "undone.json").read_text())
    page.redo_button.click()
    assert "landmark fit" in page.report_text.toPlainText() and s.report_is_current
    fitted = _median_residual(s.rig, s)

    page.left.setFocus()
    qtbot.keyClick(page.left, Qt.Key.Key_W, Qt.KeyboardModifier.ShiftModifier)  # 1 degree tilt
    assert not s.report_is_current
    assert page.report_text.toPlainText().startswith("Residuals of the current rig (moved by hand")
    s.save_rig(tmp_path / "nudged.json")
    saved = Rig.load(tmp_path / "nudged.json")
    cal = json.loads((tmp_path / "nudged.json").read_text())["calibration"]
    truth = _median_residual(saved, s)  # the saved rig's residual, computed here from the points
    assert truth > fitted + 2.0
    assert cal["method"].startswith("manual nudge")
    assert cal["per_camera"][CAM]["median_px"] == pytest.approx(truth, abs=0.05)
    assert cal["before_nudge"]["per_camera"][CAM]["median_px"] == pytest.approx(fitted, abs=0.05)
    page.undo_button.click()  # undo the nudge: the fit's report is current again
    assert s.report_is_current and "landmark fit" in page.report_text.toPlainText()


def test_quitting_with_unsaved_landmarks_or_rig_asks_first(qtbot, page, demo, tmp_path, monkeypatch):
    """Closing the window (or opening another rig) with unsaved clicks or an unsaved fitted rig
    asks before throwing them away; Cancel keeps the window and the work (before, they were lost
    without a word)."""
    from PySide6.QtWidgets import QMessageBox

    from plantreg_gui.gui.main_window import MainWindow

    rig, rec, scene = demo
    asked = []
    answer = {"button": QMessageBox.StandardButton.Cancel}

    def fake_warning(parent, title, text, *a, **k):
        asked.append(text)
        return answer["button"]

    monkeypatch.setattr(QMessageBox, "warning", staticmethod(fake_warning))
    win = MainWindow()
    qtbot.addWidget(win)
    win.show()
    s = page.session
    page.setParent(None)
    win.landmarks.set_session(s)
    qtbot.waitUntil(lambda: not win.landmarks.is_busy(), timeout=300_000)
    assert win.landmarks.confirm_discard("Quit") and not asked  # nothing edited yet
    _add_truth_points(s, rig, scene)
    assert s.unsaved() == ["landmarks"]
    assert not win.close() and win.isVisible() and len(s.points) == 12
    assert "landmarks is not saved" in asked[-1].lower()
    s.save_landmarks(tmp_path / "landmarks.json")
    assert s.unsaved() == []
    s.fit(frozenset())
    assert s.unsaved() == ["rig"]
    assert not win.close() and "rig" in asked[-1]
    s.save_rig(tmp_path / "rig.json")
    n = len(asked)
    s.nudge("rotate", 0, 0.2)
    s.undo()  # back to what was saved: nothing to lose
    assert s.unsaved() == [] and win.landmarks.confirm_discard("Quit") and len(asked) == n
    s.nudge("rotate", 0, 0.2)
    answer["button"] = QMessageBox.StandardButton.Discard
    win.landmarks.shutdown()
    assert win.close()


def test_report_heading_says_whether_the_opened_rig_was_fitted(qtbot, page, demo):
    """The report pane's heading: the shipped Plant3DImageReg rig was fitted by ``plantreg
    fit-rig`` (its file says so) and must not be called "not fitted yet"; after a nudge it is no
    longer the rig as opened (before, both read "as opened (not fitted yet)")."""
    from plantreg_gui.models.landmarks import LandmarkSession
    from plantreg_gui.gui.landmarks.page import LandmarkPage

    rig, rec, scene = demo
    text = page.report_text.toPlainText()
    assert "calibration" not in page.session.rig.extra and "not fitted yet" in text
    fitted = Rig.from_dict(rig.to_dict())
    fitted.extra["calibration"] = {"method": "landmarks", "date": "2026-11-30T11:56:02+00:00"}
    p = LandmarkPage()
    qtbot.addWidget(p)
    s = LandmarkSession(fitted, LandmarkSet(), {"plant": rec})
    s.set_camera(CAM)
    _add_truth_points(s, rig, scene)
    p.set_session(s)
    try:
        text = p.report_text.toPlainText()
        assert "not fitted yet" not in text and "fitted before: landmarks, 2026-11-30" in text
        s.nudge("rotate", 0, 1.0)
        assert p.report_text.toPlainText().startswith("Residuals of the current rig (moved by hand")
    finally:
        p.shutdown()  # the overlay's worker: also when an assertion failed


def test_views_show_colour_bars_and_the_value_under_the_cursor(qtbot, page, demo):
    """The landmark views reuse the workspace's colour bar (limits in the modality's unit) and
    read-out (Layer.value_text): the thermal view has a °C scale, the depth camera's infrared a
    unitless one, a colour camera none; moving the mouse over a view reads that image's pixel
    (before, none of it: clicking leaf corners on a thermal image without a temperature scale)."""
    from plantreg_gui.core.display import display

    rig, rec, scene = demo
    th = np.asarray(rec.images[CAM])
    bar = page.right_bar
    assert not bar.isHidden() and bar.cmap == "RdBu_r"
    lo, hi = display.auto_limits(th, (1, 99))  # what the view is drawn with (to_rgb8's default)
    assert bar.limits == pytest.approx((lo, hi))
    assert bar.lo.text() == f"{lo:.1f}" and bar.hi.text() == f"{hi:.1f} °C"
    ir = np.asarray(rec.images["ir"])
    assert not page.left_bar.isHidden() and page.left_bar.cmap == "gray"
    assert page.left_bar.limits == pytest.approx(display.auto_limits(ir, (1, 99)))
    assert not page.left_bar.hi.text().endswith("°C")  # the infrared has no unit

    # a real mouse move over the thermal view reads the thermal pixel under it, in °C
    row, col = 240, 320
    p = page.right.mapFromScene(QPointF(col + 0.5, row + 0.5))
    qtbot.mouseMove(page.right.viewport(), p)
    qtbot.waitUntil(lambda: "thermal" in page.readout.text(), timeout=5000)
    c, r = (int(v) for v in re.search(r"x=(\d+) y=(\d+):", page.readout.text()).groups())
    assert abs(r - row) <= 1 and abs(c - col) <= 1  # within the zoom's rounding
    assert page.readout.text().endswith(f"x={c} y={r}: {th[r, c]:.2f} °C")
    # the overlay is in the depth camera's grid: it reads the infrared
    page.over.hover_scene(QPointF(100.5, 200.5))
    assert page.readout.text().startswith("ir (640x576)  x=100 y=200: ") and \
        page.readout.text().endswith(f": {float(ir[200, 100]):.0f} DN")  # the rig's units (issue 21)

    # a colour camera: no colour bar, three values read out
    page.camera_combo.setCurrentText("rgb")
    assert page.right_bar.isHidden() and not page.left_bar.isHidden()
    page.right.hover_scene(QPointF(10.5, 20.5))
    px = np.asarray(rec.images["rgb"])[20, 10]
    assert page.readout.text().endswith("x=10 y=20: (" + ", ".join(f"{int(v)}" for v in px) + ")")
    qtbot.waitUntil(lambda: not page.is_busy(), timeout=300_000)
