"""Issue 21, the technician's pass in a 1280 x 720 window (a laptop; under Xvfb): texts cut and
controls below the fold. Each test measures what the technician looked at in the main window at
that size -- a label's whole text shown, a control inside the visible part of its page, the
strings the heat map paints -- and failed on the code before the fix."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

pytestmark = pytest.mark.gui

LAPTOP = (1280, 720)


def _wait(pred, timeout: float = 120.0) -> None:
    from test_gui_workspace import _wait as wait  # the event-loop wait of the workspace tests

    wait(None, pred, timeout)


def _settle(qapp, n: int = 5) -> None:
    for _ in range(n):
        qapp.processEvents()


def text_shown(label) -> bool:
    """``label`` shows its whole text: wrapped, it needs no more height than it has; on one line,
    no more width than it has."""
    if label.wordWrap():
        return label.heightForWidth(label.width()) <= label.height() + 1
    return label.fontMetrics().horizontalAdvance(label.text()) <= label.contentsRect().width()


def inside_viewport(widget, scroll) -> bool:
    """``widget`` lies wholly inside the visible part of the scroll area ``scroll``."""
    from PySide6.QtCore import QPoint, QRect

    vp = scroll.viewport()
    top_left = widget.mapTo(vp, QPoint(0, 0))
    return vp.rect().contains(QRect(top_left, widget.size()))


@pytest.fixture(scope="module")
def demo_solved(demo_dir, tmp_path_factory):
    """The demo's calibration session (a copy) detected, calibrated and tabulated in this process,
    as the wizard's worker jobs return it: (session, detections, calibration, report)."""
    from plantreg_gui.core.calibration import Session, calibrate, detect_session, error_tables

    folder = tmp_path_factory.mktemp("laptop") / "session"
    shutil.copytree(demo_dir / "calibration", folder)
    session = Session.load(folder)
    detections = {d.key: d for d in detect_session(session)}
    cal = calibrate(session, detections)
    return session, detections, cal, error_tables(session, cal, detections)


@pytest.fixture
def window(qapp, no_qt_leaks):
    """The main window at a laptop's size, shown."""
    from plantreg_gui.gui.main_window import MainWindow

    w = MainWindow()
    w.resize(*LAPTOP)
    w.show()
    _settle(qapp)
    assert (w.width(), w.height()) == LAPTOP
    yield w
    w.wizard.shutdown()
    w.workspace.shutdown()
    w.close()
    w.deleteLater()


def _wizard_on(window, qapp, solved, page: int):
    """The wizard tab showing ``page`` of the solved demo (no worker runs: the model holds it all)."""
    session, detections, cal, report = solved
    wz = window.wizard
    window.tabs.setCurrentWidget(wz)
    wz.model.set_session(session)
    for d in detections.values():
        wz.model.put_detection(d, None)
    wz.model.set_calibration(cal)
    wz.model.set_report(report)
    wz.go_to_page(page)
    assert not wz.is_busy()
    _settle(qapp)
    return wz, wz.pages[page - 1], wz.stack.currentWidget()


def test_page1_warning_and_save_are_in_view(window, qapp, demo_solved):
    """Item 3: with a symmetric board the warning and 'Save changes to session' were below the
    fold of page 1 (the page scrolled; nothing showed they were there)."""
    wz, page, scroll = _wizard_on(window, qapp, demo_solved, 1)
    page.columns.setValue(page.rows.value() + 6)  # 14 x 8: both even, symmetric
    _settle(qapp)
    assert page.message.isVisible() and "symmetric" in page.message.text()
    assert page.apply_btn.isEnabled()
    assert scroll.verticalScrollBar().value() == 0
    for w in (page.message, page.apply_btn):
        assert inside_viewport(w, scroll), w
    assert text_shown(page.message)


def test_page4_heat_map_texts_are_whole(window, qapp, demo_solved, monkeypatch):
    """Item 2: the heat maps' titles and captions were elided ("least certai…", "hatched…") in
    the four panels of a 1280 x 720 window. Every title and caption the map paints must fit
    where it is painted."""
    from PySide6.QtCore import QRect, QRectF

    from plantreg_gui.gui.calibration import charts

    painted = []

    class Recording(charts.QPainter):
        def drawText(self, *args):  # noqa: N802 - Qt name
            if isinstance(args[0], (QRect, QRectF)) and isinstance(args[-1], str):
                rect, text = QRectF(args[0]), args[-1]
                flags = int(getattr(args[1], "value", args[1])) if len(args) == 3 else 0
                need = self.fontMetrics().boundingRect(rect.toAlignedRect(), flags, text)
                fits = need.width() <= rect.width() + 1 and need.height() <= rect.height() + 1
                painted.append((text, fits or (text, rect.getRect(), need.getRect())))
            elif isinstance(args[-1], str):
                painted.append((args[-1], True))
            return super().drawText(*args)

    wz, page, _scroll = _wizard_on(window, qapp, demo_solved, 4)
    umap = page.umap
    assert umap.isVisible() and umap.width() < 500  # four panels in the space a laptop leaves
    monkeypatch.setattr(charts, "QPainter", Recording)
    umap.repaint()
    texts = [t for t, _ok in painted]
    assert not [t for t in texts if "…" in t]
    assert not [ok for t, ok in painted if ok is not True and " " in t]  # titles and captions (not tick labels)
    for m in charts_titles(demo_solved):
        assert m in texts  # each camera's title, whole
    assert any("hatched" in t and "no board" in t for t in texts)


def charts_titles(solved) -> list[str]:
    from plantreg_gui.gui.calibration import results

    return [m["title"] for m in results.uncertainty_maps(solved[2])]


def test_page5_fits_the_width_and_its_legend_names_every_camera(window, qapp, demo_solved):
    """Item 1: page 5 was wider than a 1280 px window (two long group titles), so the 3D view's
    legend in its top right corner was cut off; the legend is now a label under the view."""
    wz, page, scroll = _wizard_on(window, qapp, demo_solved, 5)
    _wait(lambda: page.view3d.n_frusta == len(demo_solved[2].rig.cameras) or page.view3d.error is not None, 60)
    _settle(qapp)
    assert scroll.horizontalScrollBar().maximum() == 0  # nothing to the right of the window's edge
    assert inside_viewport(page.view3d, scroll)
    for name in demo_solved[2].rig.names:
        assert name in page.legend.text()
    assert page.legend.isVisible() and text_shown(page.legend) and inside_viewport(page.legend, scroll)


def test_red_cells_are_explained(qtbot):
    """Item 5: on the Lepton 3.5 + ZED 2i set page 5 shows rgb -> thermal red (0.44 px on the
    120 x 160 thermal image: normalised 0.44 * 1000 / sqrt(120 * 160) = 3.18) with no word on
    what red means. A report with those figures (the published set's, docs/calibration.md) must
    say which cell is red, what red means and what commonly causes it; one without a red cell
    says nothing."""
    from PySide6.QtCore import QObject, Signal

    from plantreg_gui.gui.calibration.extrinsics_page import ExtrinsicsPage
    from plantreg_gui.gui.calibration.widgets import GRADE_MAX, grade_colour
    from plantreg_gui.models.calibration import WizardModel

    class Actions(QObject):
        busy_changed = Signal(bool)

        def is_busy(self) -> bool:
            return False

    def cell(px, w, h):
        return {"px": px, "normalized": px * 1000 / np.sqrt(w * h)}

    sizes = {"rgb": (1280, 720), "thermal": (120, 160)}
    report = {"extrinsic": {"rgb": {"thermal": cell(0.44, *sizes["thermal"])},
                            "thermal": {"rgb": cell(2.58, *sizes["rgb"])}},
              "cameras": {c: {"width": w, "height": h, "normalization": 1000 / np.sqrt(w * h)}
                          for c, (w, h) in sizes.items()},
              "views": {"extrinsic": {"rgb": {"thermal": {"t_1": 0.2, "t_2": 0.9, "t_3": 0.5, "t_4": 0.1}}}}}
    assert report["extrinsic"]["rgb"]["thermal"]["normalized"] == pytest.approx(3.175, abs=1e-3)
    m = WizardModel()
    page = ExtrinsicsPage(m, Actions())
    qtbot.addWidget(page)
    page.resize(1050, 600)
    page.show()
    m.set_report(report)
    page.refresh()
    assert grade_colour(3.175) == grade_colour(GRADE_MAX)  # the cell is red
    note = page.red_note.text()
    qtbot.waitUntil(lambda: text_shown(page.red_note), timeout=5000)  # the whole note, not its middle
    assert "rgb → thermal 0.44 px of thermal's 120 × 160 = 3.18 normalised" in note
    assert "thermal → rgb" not in note  # 2.69: orange, not red
    assert "(worst views t_2, t_3, t_1)" in note
    assert "per 1000 px of the target image" in note and "same moment" in note
    report["extrinsic"]["rgb"]["thermal"] = cell(0.30, *sizes["thermal"])  # 2.17: no red cell
    m.set_report(report)
    page.refresh()
    assert not page.red_note.isVisible() and page.red_note.text() == ""


def _registered_window(window, qapp, demo_registered, view: str):
    from conftest import workspace_session_outputs

    ws = window.workspace
    loaded, reg = workspace_session_outputs(demo_registered)
    ws.session.apply_loaded(loaded)
    ws._registered(reg)
    ws.set_view(view)
    _settle(qapp)
    return ws


def test_mosaic_mode_reads_whole(window, qapp, demo_registered):
    """Item 4: the mosaic's Mode combo read "Mosaic (a" in a 1280 px window."""
    from PySide6.QtWidgets import QComboBox

    ws = _registered_window(window, qapp, demo_registered, "mosaic")
    mv = ws.views["mosaic"]
    for combo in (mv.mode, mv.a, mv.b):
        probe = QComboBox()  # the same entries, as wide as the longest needs
        probe.setFont(combo.font())
        probe.addItems([combo.itemText(i) for i in range(combo.count())])
        probe.setSizeAdjustPolicy(QComboBox.SizeAdjustPolicy.AdjustToContents)
        assert combo.width() >= probe.sizeHint().width(), (combo.currentText(), combo.width())
        probe.deleteLater()


def test_side_by_side_titles_and_read_out_are_whole(window, qapp, demo_registered):
    """Item 6: in the side-by-side view at 1280 px the hyperspectral view's title was cut, and so
    was the end of the cursor's read-out in the status bar (five cameras, case and area)."""
    ws = _registered_window(window, qapp, demo_registered, "side-by-side")
    grid = ws.views["side-by-side"]
    assert "hyperspectral" in grid.views
    for name, tv in grid.views.items():
        assert text_shown(tv.label), (name, tv.label.text(), tv.label.width())
    s = ws.session
    r = s.result
    rows, cols = np.nonzero(r.cases[s.masks_source] > 0)  # a pixel with a case: the longest read-out
    s.hover("target", int(rows[len(rows) // 2]), int(cols[len(cols) // 2]))
    _settle(qapp)
    assert "case:" in s.readout and "area:" in s.readout
    assert ws.readout.text() == s.readout
    assert text_shown(ws.readout), ws.readout.text()


def test_page5_screenshot_shows_the_frusta(window, qapp, demo_solved, tmp_path):
    """The window's screenshot (as `plantreg-gui --screenshot` and figures/wizard_screenshots.py
    take it) shows the 3D view's picture at 1280 x 720: page 5's layout settles while the view
    is still building, so its first resizes can come before VTK's first frame. (A resize split
    over later turns once left the view black in figures/wizard_screenshots.py on the Lepton
    set; this test did not reproduce that trigger, with the demo or with a third of the Lepton
    pairs: it guards the outcome, the screenshot looked at is the check of the cause.)"""
    import time

    from PIL import Image
    from PySide6.QtCore import QPoint

    solved = demo_solved
    wz, page, scroll = _wizard_on(window, qapp, solved, 5)
    _wait(lambda: page.view3d.n_frusta == len(solved[2].rig.cameras) or page.view3d.error is not None, 60)
    assert page.view3d.error is None
    t = time.monotonic()
    while time.monotonic() - t < 1.0:
        qapp.processEvents()
        time.sleep(0.02)
    out = tmp_path / "page5.png"
    window.save_screenshot(out)
    img = np.asarray(Image.open(out).convert("RGB"))
    dpr = window.devicePixelRatioF()
    widget = page.view3d.plotter or page.view3d
    at = widget.mapTo(window, QPoint(0, 0))
    x, y, w, h = (round(v * dpr) for v in (at.x(), at.y(), widget.width(), widget.height()))
    assert w > 100 and h > 100
    crop = img[y:y + h, x:x + w].reshape(-1, 3)
    assert len(np.unique(crop[:: max(1, len(crop) // 20000)], axis=0)) > 20  # a picture, not a fill


def test_page5_tables_are_whole_at_1280(window, qapp, demo_solved):
    """Page 5 at 1280 x 720 with the demo's four cameras: both tables in view without a
    sideways scroll (the poses' last column, "σ rig px med / worst", and "→ hyperspectral" were
    cut), every camera name whole, and the poses table above the fold (it sat under the red
    cells' note)."""
    wz, page, scroll = _wizard_on(window, qapp, demo_solved, 5)
    _wait(lambda: page.view3d.n_frusta == len(demo_solved[2].rig.cameras) or page.view3d.error is not None, 60)
    _settle(qapp, 20)
    for table in (page.table, page.poses):
        table.horizontalScrollBar().setValue(0)
        assert table.horizontalScrollBar().maximum() == 0, table
        hh = table.horizontalHeader()
        fm = hh.fontMetrics()
        for j in range(table.columnCount()):
            words = table.horizontalHeaderItem(j).text().split("\n")
            assert max(fm.horizontalAdvance(w) for w in words) <= hh.sectionSize(j), words
    fm = page.poses.fontMetrics()
    bold = page.poses.item(0, 0).font()
    from PySide6.QtGui import QFontMetrics

    fmb = QFontMetrics(bold)
    for i in range(page.poses.rowCount()):
        for line in page.poses.item(i, 0).text().split("\n"):
            assert fmb.horizontalAdvance(line) <= page.poses.columnWidth(0), line
    assert inside_viewport(page.poses, scroll)



@pytest.mark.parametrize("size", [LAPTOP, (1500, 950)])
def test_page4_bar_chart_titles_are_whole(window, qapp, demo_solved, monkeypatch, size):
    """Issue 21 (session 14): page 4's per-view bar-chart titles ("rgb: error per view (mean
    ... px, dashed), 1 weak") were painted on one line centred on the plot area; wider than the
    panel, their start was cut off at the chart's left edge (1280 x 720 and 1500 x 950). Every
    title must be painted whole, inside the chart."""
    from PySide6.QtCore import QRect, QRectF

    from plantreg_gui.gui.calibration import charts

    window.resize(*size)
    _settle(qapp)
    painted = []

    class Recording(charts.QPainter):
        def drawText(self, *args):  # noqa: N802 - Qt name
            if isinstance(args[-1], str) and "error per view" in args[-1]:
                if isinstance(args[0], (QRect, QRectF)):
                    flags = int(getattr(args[1], "value", args[1])) if len(args) == 3 else 0
                    need = QRectF(self.fontMetrics().boundingRect(QRectF(args[0]).toAlignedRect(), flags, args[-1]))
                else:  # at a point: one line from there
                    pt = args[0]
                    need = QRectF(pt.x(), pt.y() - self.fontMetrics().ascent(),
                                  self.fontMetrics().horizontalAdvance(args[-1]), self.fontMetrics().height())
                painted.append((args[-1], need))
            return super().drawText(*args)

    wz, page, _scroll = _wizard_on(window, qapp, demo_solved, 4)
    chart = page.chart
    assert chart.isVisible()
    monkeypatch.setattr(charts, "QPainter", Recording)
    chart.repaint()
    cams = [c for c in demo_solved[2].rig.names if chart.bars.get(c) or chart.excluded_bars.get(c)]
    assert len(painted) == len(cams) >= 2
    for cam in cams:
        assert any(t.startswith(f"{cam}: error per view") for t, _r in painted)
    for text, need in painted:
        assert need.left() >= 0 and need.right() <= chart.width(), (text, need.getRect(), chart.width())
        assert need.top() >= 0, (text, need.getRect())


LEPTON_RED_NOTE = (  # the red note of page 5 on the Lepton 3.5 + ZED 2i set (tests/realcal.py), as shown
    "Red cells (normalised error ≥ 3): rgb → thermal 0.44 px of thermal's 120 × 160 = 3.16 normalised "
    "(worst views t_20251006_103851, t_20251006_103852, t_20251006_103914). Red means that the origin "
    "camera's corners, carried through the calibrated rig, miss the target camera's corners by more than "
    "3 px per 1000 px of the target image's size: on a small image a fraction of a pixel is already red. "
    "Usual causes: the cameras did not see the board at the same moment (a hand-held board, cameras not "
    "triggered together), a camera moved between views, or mislocated corners (look at the worst views on "
    "page 3). thermal's corners fit the joint rig 4.3 × worse than its own lens model (0.75 against 0.18 px "
    "per coordinate): its views disagree with one rigid rig, as when the board moves between the cameras' "
    "exposures.")


def test_page5_poses_table_in_view_with_a_long_red_note(window, qapp, demo_solved, monkeypatch):
    """Issue 21 (session 14): on the Lepton + ZED set at 1280 x 720 the red cells' note (ten lines)
    pushed the camera poses table below the fold: page 5 had to be scrolled to reach it. The table
    must be in view without scrolling, and the note's whole text readable."""
    from plantreg_gui.gui.calibration import results

    monkeypatch.setattr(results, "red_cells_note", lambda *a, **k: LEPTON_RED_NOTE)
    wz, page, scroll = _wizard_on(window, qapp, demo_solved, 5)
    _wait(lambda: page.view3d.n_frusta == len(demo_solved[2].rig.cameras) or page.view3d.error is not None, 60)
    _settle(qapp, 10)
    assert page.red_note.isVisible() and page.red_note.text() == LEPTON_RED_NOTE
    assert inside_viewport(page.poses, scroll)  # the note comes after both tables (the page may scroll to it)
    assert page.poses.verticalScrollBar().maximum() == 0  # every camera's row
    assert page.red_note.height() >= page.red_note.heightForWidth(page.red_note.width())  # whole text
    assert inside_viewport(page.table, scroll)


def test_page5_poses_table_fits_1500_wide(window, qapp, demo_solved):
    """Issue 21 (session 14): page 5's poses table needed a sideways scroll for its last column
    ("σ rig px med/worst") in a 1500 px window. Headers are short, on two lines, with tooltips."""
    window.resize(1500, 950)
    _settle(qapp)
    wz, page, scroll = _wizard_on(window, qapp, demo_solved, 5)
    _settle(qapp, 10)
    t = page.poses
    assert t.isVisible() and t.columnCount() == 9
    assert t.horizontalScrollBar().maximum() == 0
    hh = t.horizontalHeader()
    assert hh.sectionPosition(8) + hh.sectionSize(8) <= t.viewport().width()
    last = t.horizontalHeaderItem(8)
    assert "σ rig px" in last.text() and "median" in last.toolTip() and "worst" in last.toolTip()
