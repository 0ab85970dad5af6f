"""The registration workspace (issue 5) driven like a user would, under Xvfb.

One workspace is registered once per module (demo rig + recording, target ``ir``) while the
GUI thread's event-loop latency is measured; the tests then check what each view shows against
values computed independently from the registration result (display rendering of the registered
arrays, case counts, raw values in their units), the export files against the result, and the
Plant3DImageReg reader against the data set's documented layout and the nominal optics.
"""

from __future__ import annotations

import math
import shutil
import time
from pathlib import Path

import numpy as np
import pytest

pytestmark = pytest.mark.gui


def _wait(qapp, pred, timeout: float = 120.0) -> None:
    """Run the Qt event loop until ``pred()`` is true (fails after ``timeout`` seconds).

    Processes events and sleeps instead of a nested event loop quit by a timer: if such a loop
    returns at once (it does once the application is quitting), every pass would leave a pending
    timer behind -- millions of them, and the teardown's event processing never ends."""
    from PySide6.QtCore import QEventLoop
    from PySide6.QtWidgets import QApplication

    t0 = time.monotonic()
    while not pred():
        if time.monotonic() - t0 > timeout:
            pytest.fail("timed out waiting for the workspace")
        QApplication.processEvents(QEventLoop.ProcessEventsFlag.AllEvents, 10)
        time.sleep(0.005)


@pytest.fixture
def ws(qapp, demo_dir, tmp_path_factory):
    """A shown workspace with the demo opened and registered into ``ir`` (a new one per test:
    what one test changes never reaches the next)."""
    from PySide6.QtCore import QSettings

    from plantreg_gui.gui.registration.workspace import RegistrationWorkspace

    settings_dir = str(tmp_path_factory.mktemp("qsettings"))  # keep the user's recent files out of it
    for fmt in (QSettings.Format.NativeFormat, QSettings.Format.IniFormat):
        QSettings.setPath(fmt, QSettings.Scope.UserScope, settings_dir)
    w = RegistrationWorkspace()
    w.resize(1400, 900)
    w.show()
    w.open_rig(demo_dir / "rig.json")
    w.open_recording(demo_dir / "recording")
    _wait(qapp, lambda: not w.is_busy())
    w.raw_shown = {n: tv.view.displayed() for n, tv in w.raw_grid.views.items()}  # before any registration
    w.raw_result = w.result
    w.run_registration("ir")
    _wait(qapp, lambda: w.result is not None and not w.is_busy())
    yield w
    w.shutdown()
    w.close()
    w.deleteLater()


def test_raw_images_shown_before_registration(ws, demo_dir):
    from plantreg_gui.core.display import display
    from plantreg_gui.core.data.recording import Recording
    from plantreg_gui.core.camera.rig import Rig

    rig = Rig.load(demo_dir / "rig.json")
    rec = Recording.load(demo_dir / "recording", rig)
    assert ws.raw_result is None
    assert set(ws.raw_shown) == {"depth", *rec.images}
    for cam, img in rec.images.items():
        expected = display.to_rgb8(img, modality=rig.camera(cam).modality)
        assert ws.raw_shown[cam].shape == (*img.shape[:2], 3)
        np.testing.assert_array_equal(ws.raw_shown[cam], expected)
    # the raw depth is shown in millimetres
    d_mm = rec.depth.astype(np.float32) * np.float32(rig.depth_scale * 1000)
    d_mm[~(d_mm > 0)] = np.nan
    np.testing.assert_array_equal(ws.raw_shown["depth"], display.to_rgb8(d_mm, modality="depth"))


def test_side_by_side_shows_display_rendering_of_registered_arrays(ws):
    from plantreg_gui.core.display import display

    r = ws.result
    ws.set_view("side-by-side")
    assert ws.current_view() == "side-by-side"
    assert set(ws.sbs_grid.views) == set(r.registered) | {"depth"}
    for cam, arr in r.registered.items():
        # a cube is drawn with its raw cube's PCA basis (the same colour raw and registered)
        raw = ws.recording.images[cam]
        pca = display.fit_pca(raw) if raw.ndim == 3 and raw.shape[2] > 4 else None
        expected = display.to_rgb8(arr, modality=ws.rig.camera(cam).modality, pca=pca)
        np.testing.assert_array_equal(ws.sbs_grid.views[cam].view.displayed(), expected)
    z_mm = r.points_rig[..., 2] * 1000
    np.testing.assert_array_equal(ws.sbs_grid.views["depth"].view.displayed(),
                                  display.to_rgb8(z_mm.astype(np.float32), modality="depth"))


def test_linked_cursor_and_readout_in_units(ws):
    r = ws.result
    rows, cols = np.nonzero(np.isfinite(r.registered["thermal"]) & np.isfinite(r.points_rig[..., 2]))
    row, col = int(rows[len(rows) // 2]), int(cols[len(cols) // 2])
    view = ws.sbs_grid.views["ir"].view
    view.hovered.emit(row, col)
    text = ws.readout.text()
    assert f"x={col} y={row}" in text
    assert f"thermal: {r.registered['thermal'][row, col]:.2f} °C" in text
    assert f"depth: {r.points_rig[row, col, 2] * 1000:.1f} mm" in text
    ir_text = text.split("ir: ", 1)[1].split()[0]
    assert float(ir_text) == pytest.approx(float(r.registered["ir"][row, col]), rel=1e-3)
    # the crosshair is drawn in every linked view at the pixel centre
    for tv in ws.sbs_grid.views.values():
        assert tv.view._hline.isVisible() and tv.view._vline.isVisible()
        assert tv.view._hline.pos().y() == pytest.approx(row + 0.5)
        assert tv.view._vline.pos().x() == pytest.approx(col + 0.5)
    # the spectrum plot holds the hyperspectral values of that pixel
    np.testing.assert_allclose(ws.spectrum.current, r.registered["hyperspectral"][row, col])
    # linked zoom: zooming one view zooms all
    view.zoom_by(2.0)
    scales = {round(tv.view.transform().m11(), 6) for tv in ws.sbs_grid.views.values()}
    assert len(scales) == 1


def test_display_controls_recolour_every_view(ws, qapp):
    from plantreg_gui.core.display import display
    from plantreg_gui.models.layers import DisplaySettings

    r = ws.result
    ws.controls.apply("thermal", DisplaySettings(cmap="gray", percentiles=(5.0, 95.0)))
    expected = display.to_rgb8(r.registered["thermal"], modality="thermal", cmap="gray", percentiles=(5, 95))
    np.testing.assert_array_equal(ws.sbs_grid.views["thermal"].view.displayed(), expected)
    ws.controls.apply("hyperspectral", DisplaySettings(bands=(10, 50, 90)))
    expected = display.to_rgb8(r.registered["hyperspectral"], modality="hyperspectral", bands=(10, 50, 90))
    np.testing.assert_array_equal(ws.sbs_grid.views["hyperspectral"].view.displayed(), expected)
    # the defaults are the paper's: thermal in a diverging blue-white-red map
    ws.controls.apply("thermal", DisplaySettings())
    ws.controls.apply("hyperspectral", DisplaySettings())
    lut = display.colormap_lut(display.DEFAULT_CMAPS["thermal"])
    assert lut[0, 2] > lut[0, 0] and lut[-1, 0] > lut[-1, 2] and lut[128].min() > 200


def test_mosaic_blend_flicker(ws):
    m = ws.mosaic_view
    ws.set_view("mosaic")
    order = m.order
    assert order[0] == "ir" and set(order) == set(ws.result.registered)
    m.set_mode("mosaic")
    m.tile.setValue(40)
    shown = m.view.displayed()
    n = len(order)
    for i, j in ((0, 0), (0, 1), (1, 0), (2, 3), (5, 7)):
        k = (i + j) % n
        block = (slice(i * 40, (i + 1) * 40), slice(j * 40, (j + 1) * 40))
        np.testing.assert_array_equal(shown[block], ws.renders[order[k]][block])
    m.set_mode("blend")
    m.a.setCurrentText("thermal")
    m.b.setCurrentText("rgb")
    m.alpha.setValue(0)
    np.testing.assert_array_equal(m.view.displayed(), ws.renders["thermal"])
    m.alpha.setValue(100)
    np.testing.assert_array_equal(m.view.displayed(), ws.renders["rgb"])
    m.alpha.setValue(50)
    half = (ws.renders["thermal"].astype(int) + ws.renders["rgb"].astype(int)) / 2
    assert np.abs(m.view.displayed().astype(int) - half).max() <= 1
    m.flicker.setChecked(True)
    assert m._flick_timer.isActive()
    np.testing.assert_array_equal(m.view.displayed(), ws.renders["thermal"])
    m._flick()
    np.testing.assert_array_equal(m.view.displayed(), ws.renders["rgb"])
    m.flicker.setChecked(False)
    assert not m._flick_timer.isActive()


def test_mosaic_enables_only_controls_that_change_the_picture(ws):
    """In every mode, a control is enabled exactly when moving it changes what is shown."""
    m = ws.mosaic_view
    ws.set_view("mosaic")
    controls = {
        "A": (m.a, lambda: m.a.setCurrentIndex((m.a.currentIndex() + 1) % m.a.count())),
        "B": (m.b, lambda: m.b.setCurrentIndex((m.b.currentIndex() + 2) % m.b.count())),
        "tile": (m.tile, lambda: m.tile.setValue(m.tile.value() + 17)),
        "blend": (m.alpha, lambda: m.alpha.setValue((m.alpha.value() + 30) % 100)),
    }
    try:
        for mode in ("mosaic", "checkerboard", "blend"):
            m.set_mode(mode)
            for name, (widget, move) in controls.items():
                m.a.setCurrentText("thermal")
                m.b.setCurrentText("rgb")
                m.alpha.setValue(50)
                before = m.composite().copy()
                move()
                changed = not np.array_equal(m.composite(), before)
                assert widget.isEnabled() == changed, (mode, name, widget.isEnabled(), changed)
        m.set_mode("blend")
        m.flicker.setChecked(True)  # flicker shows A or B whole: only A and B matter
        assert m.a.isEnabled() and m.b.isEnabled()
        assert not m.tile.isEnabled() and not m.alpha.isEnabled()
    finally:
        m.flicker.setChecked(False)
        m.set_mode("mosaic")


def test_mask_overlays_and_legend_counts(ws):
    from PySide6.QtCore import Qt

    r = ws.result
    mv = ws.masks_view
    ws.set_view("masks")
    counts = r.case_counts()
    n = r.area.size
    for src in r.cases:
        mv.set_source(src)
        shown = {c: mv.case_legend.counts[c] for c in mv.case_legend.codes}
        assert {c: v for c, v in shown.items() if v} == counts[src]
        assert sum(shown.values()) == n
        pct = float(mv.case_legend.item(mv.case_legend.codes.index(1), 2).text())
        assert pct == pytest.approx(100 * counts[src].get(1, 0) / n, abs=0.051)
    areas = dict(zip(*np.unique(r.area, return_counts=True)))
    assert {c: v for c, v in mv.area_legend.counts.items() if v} == {int(k): int(v) for k, v in areas.items()}
    # P2 pixels are drawn cyan at full opacity, P1 pixels keep the (grey) image
    src = max(r.cases, key=lambda s: int((r.cases[s] == 2).sum()))
    mv.set_source(src)
    mv.show_areas.setChecked(False)
    mv.show_cases.setChecked(True)
    mv.opacity.setValue(100)
    shown = mv.view.displayed()
    p2 = r.cases[src] == 2
    assert p2.any()
    assert np.all(shown[p2] == (0, 255, 255))
    p1 = r.cases[src] == 1
    assert np.all(shown[p1][:, 0] == shown[p1][:, 1])
    # unticking P2 in the legend removes its overlay
    row = mv.case_legend.codes.index(2)
    mv.case_legend.item(row, 0).setCheckState(Qt.CheckState.Unchecked)
    shown = mv.view.displayed()
    assert np.all(shown[p2][:, 0] == shown[p2][:, 1])  # grey again
    mv.case_legend.item(row, 0).setCheckState(Qt.CheckState.Checked)
    # the area map: P4 green
    mv.show_cases.setChecked(False)
    mv.show_areas.setChecked(True)
    shown = mv.view.displayed()
    assert np.all(shown[r.area == 4] == (0, 255, 0))
    mv.opacity.setValue(60)


def test_cloud_view_colours_and_picking(ws, qapp):
    r = ws.result
    ws.set_view("3d")
    _wait(qapp, lambda: ws.cloud_view.plotter is not None and not ws.cloud_view.building, 30)  # staged build
    cv = ws.cloud_view
    ok = np.all(np.isfinite(r.points_rig), axis=2)
    assert cv._poly is not None and cv._poly.n_points == int(ok.sum())
    cv.colour.setCurrentText("thermal")
    np.testing.assert_array_equal(np.asarray(cv._poly.point_data["colour"]), ws.renders["thermal"][ok])
    # both meshes of the registrar are available and can be shown
    assert all(cb.isEnabled() for cb in cv.mesh_boxes.values())
    cv.mesh_boxes["object mesh"].setChecked(True)
    assert cv._mesh_actors["object mesh"].GetVisibility()
    cv.mesh_boxes["object mesh"].setChecked(False)
    # picking a point reads out every modality at that point
    rows, cols = np.nonzero(ok & np.isfinite(r.registered["thermal"]))
    row, col = int(rows[0]), int(cols[0])
    i = cv.pick(r.points_rig[row, col])
    assert cv.cloud.pixels[i] == row * r.area.shape[1] + col
    text = cv.info.text()
    assert f"thermal: {r.registered['thermal'][row, col]:.2f} °C" in text
    assert f"z={r.points_rig[row, col, 2] * 1000:.1f} mm" in text
    ws.prepare_screenshot()


def test_export_writes_files_and_asks_before_overwriting(ws, qapp, tmp_path, monkeypatch):
    import tifffile
    import cv2
    from PySide6.QtWidgets import QMessageBox

    r = ws.result
    out = tmp_path / "export"
    asked = []
    monkeypatch.setattr(QMessageBox, "question", lambda *a, **k: asked.append(a) or QMessageBox.StandardButton.No)
    assert ws.export(out)
    _wait(qapp, lambda: not ws.is_busy())
    assert not asked and ws.last_export == out
    for cam, arr in r.registered.items():
        tif = tifffile.imread(out / "registered" / f"{cam}.tif")
        np.testing.assert_array_equal(tif, arr)  # NaN == NaN for array_equal in numpy testing
        assert (out / "registered" / f"{cam}.png").is_file()
    for cam, codes in r.cases.items():
        np.testing.assert_array_equal(cv2.imread(str(out / "cases" / f"{cam}.png"), cv2.IMREAD_UNCHANGED), codes)
    np.testing.assert_array_equal(cv2.imread(str(out / "areas.png"), cv2.IMREAD_UNCHANGED), r.area)
    from plyfile import PlyData

    ply = PlyData.read(str(out / "pointcloud.ply"))
    assert ply["vertex"].count == int(np.all(np.isfinite(r.points_rig), axis=2).sum())
    assert (out / "mosaic.png").is_file() and (out / "summary.json").is_file()
    stamp = (out / "summary.json").stat().st_mtime_ns
    # an existing folder: "No" leaves it alone, "Yes" replaces it
    assert not ws.export(out, ["summary"])
    assert len(asked) == 1 and (out / "summary.json").stat().st_mtime_ns == stamp
    monkeypatch.setattr(QMessageBox, "question", lambda *a, **k: QMessageBox.StandardButton.Yes)
    assert ws.export(out, ["summary", "areas"])
    _wait(qapp, lambda: not ws.is_busy())
    assert sorted(p.name for p in out.iterdir()) == ["areas.png", "summary.json"]


def test_export_dialog_needs_a_folder_and_a_part(qapp, tmp_path):
    """An empty folder field would export into (and offer to replace) the current directory;
    nothing ticked would write an empty folder: Export stays disabled until both are given."""
    from PySide6.QtWidgets import QDialogButtonBox

    from plantreg_gui.core.export.export import OUTPUTS
    from plantreg_gui.gui.registration.export_dialog import ExportDialog

    dlg = ExportDialog(tmp_path / "out")
    ok = dlg.buttons.button(QDialogButtonBox.StandardButton.Ok)
    try:
        assert ok.isEnabled() and dlg.what() == list(OUTPUTS)  # every core output is offered
        dlg.folder.setText("   ")
        assert not ok.isEnabled()
        dlg.folder.setText(str(tmp_path / "out2"))
        assert ok.isEnabled() and dlg.out() == tmp_path / "out2"
        for cb in dlg.boxes.values():
            cb.setChecked(False)
        assert not ok.isEnabled()
        dlg.boxes["summary"].setChecked(True)
        assert ok.isEnabled() and dlg.what() == ["summary"]
    finally:
        dlg.deleteLater()


def test_export_proposes_a_folder_beside_the_recording(ws, demo_dir):
    # named for the recording: a data set's plants lie side by side, and a shared default folder
    # let each plant's export replace the last one's (technician pass, session 14, M2)
    assert ws.default_export_folder() == demo_dir / "recording-registered-ir"


def test_recent_files_remember_what_was_opened(ws, demo_dir):
    rec = ws.recent()
    assert f"pair:{demo_dir / 'rig.json'}|{demo_dir / 'recording'}" in rec  # the pair, reopened together
    assert f"rig:{demo_dir / 'rig.json'}" in rec


def test_registering_another_target_reuses_the_registrar(ws, qapp):
    registrar = ws.registrar
    ws.run_registration("thermal")
    _wait(qapp, lambda: ws.result.target == "thermal" and not ws.is_busy())
    assert ws.registrar is registrar
    assert ws.result.area.shape == ws.rig.camera("thermal").shape
    assert ws.sbs_grid.views["rgb"].view.displayed().shape[:2] == (480, 640)
    assert set(ws.masks_view.cases) == {"ir", "rgb", "hyperspectral"}


def test_cancel_registration(ws, qapp):
    ws.session.registrar = None  # rebuild the meshes: long enough to cancel
    before = ws.result
    ws.run_registration("ir")
    assert ws.is_busy()
    ws.cancel()
    _wait(qapp, lambda: not ws.is_busy())
    assert ws.result is before
    assert "cancelled" in ws.readout.text()


def test_worker_error_becomes_a_dialog(qapp, demo_dir, tmp_path, monkeypatch):
    from PySide6.QtWidgets import QMessageBox

    from plantreg_gui.core.io.imageio import write_tiff
    from plantreg_gui.gui.registration.workspace import RegistrationWorkspace

    rec = tmp_path / "recording"
    shutil.copytree(demo_dir / "recording", rec)
    write_tiff(rec / "thermal.tif", np.zeros((100, 120), np.float32))  # wrong size for the thermal camera
    w = RegistrationWorkspace()
    w.show()
    asked = []
    # a recording that does not fit the open rig: the question names the file and the misfit
    monkeypatch.setattr(QMessageBox, "question", lambda *a, **k: asked.append(a[2]) or QMessageBox.StandardButton.No)
    try:
        w.open_rig(demo_dir / "rig.json")
        w.open_recording(rec)
        _wait(qapp, lambda: not w.is_busy())
        assert len(asked) == 1
        assert "120x100" in asked[0] and "thermal" in asked[0] and "thermal.tif" in asked[0]
        assert w.recording is None and not w.register_button.isEnabled()
        w.open_recording(tmp_path / "nowhere")  # a job's error: a dialog naming the folder
        _wait(qapp, lambda: not w.is_busy())
        boxes = [b for b in w.findChildren(QMessageBox) if b.objectName() == "errorDialog" and b.isVisible()]
        assert len(boxes) == 1 and "nowhere" in boxes[0].text()
        boxes[0].close()
    finally:
        w.shutdown()
        w.deleteLater()


# ---------------------------------------------------------------------- Plant3DImageReg
def test_plant3d_reader_and_nominal_optics(shared_data):
    from plantreg_gui.core.data import plant3d

    folder = shared_data / "plant3dimagereg"
    plants = plant3d.list_plants(folder)
    assert plants == ["01grapevine", "02leopard_lily", "03areca_palm", "04philodendron", "05boston_fern",
                      "06weeping_fig"]
    K = plant3d.nominal_intrinsics()
    # the corner rays of the nominal model span the NFOV's 75 x 65 degrees
    assert 2 * math.degrees(math.atan((640 / 2) / K[0, 0])) == pytest.approx(75.0)
    assert 2 * math.degrees(math.atan((576 / 2) / K[1, 1])) == pytest.approx(65.0)
    p = plant3d.load_plant(folder, "01grapevine")
    assert p.images["depth"].shape == (576, 640) and p.images["ir"].shape == (576, 640)
    assert p.images["thermal"].shape == (480, 640) and p.images["hs render"].shape == (512, 512, 3)
    assert 10 < float(np.mean(p.images["thermal"])) < 40  # degrees C as the data set says
    depth = p.images["depth"]
    assert len(p.points) == int((depth > 0).sum())
    # back-projection: the z of each point is its depth; x/z follows the pixel column
    i = len(p.points) // 3
    v, u = divmod(int(p.point_pixels[i]), 640)
    assert p.points[i, 2] == pytest.approx(depth[v, u] / 1000.0)
    assert p.points[i, 0] / p.points[i, 2] == pytest.approx((u - K[0, 2]) / K[0, 0], rel=1e-5)
    assert "No calibration ships with this data set" in p.note


def test_plant3d_opens_in_the_workspace_with_a_banner(qapp, shared_data):
    from plantreg_gui.gui.registration.workspace import RegistrationWorkspace

    folder = shared_data / "plant3dimagereg"
    w = RegistrationWorkspace()
    w.resize(1300, 850)
    w.show()
    try:
        w.open_plant3d(folder, "03areca_palm")
        _wait(qapp, lambda: not w.is_busy())
        assert w.plant is not None and w.banner.isVisible()
        assert "No calibration ships with this data set: registration needs a rig file" in w.banner.text()
        assert set(w.raw_grid.views) == {"depth", "ir", "thermal", "hs render", "hs pca"}
        assert not w.register_button.isEnabled()
        # the views that need a registration say why they are empty instead of a blank pane
        for key in ("side-by-side", "mosaic", "masks"):
            assert not w.empty_notes[key].isHidden()
            assert "no calibration ships with this data set" in w.empty_notes[key].text()
        assert w.empty_notes["raw"].isHidden() and w.empty_notes["3d"].isHidden()
        th = w.plant.images["thermal"]
        w.raw_grid.views["thermal"].view.hovered.emit(100, 200)
        assert f"{th[100, 200]:.2f} °C" in w.readout.text()
        w.raw_grid.views["depth"].view.hovered.emit(288, 320)
        d = w.plant.images["depth"][288, 320]
        assert (f"{float(d):.1f} mm" if d > 0 else "—") in w.readout.text()
        assert len(w.cloud.points) == int((w.plant.images["depth"] > 0).sum())
        w.set_view("3d")
        _wait(qapp, lambda: w.cloud_view._poly is not None and not w.cloud_view.building, 30)
        assert w.cloud_view._poly.n_points == len(w.cloud.points)
    finally:
        w.shutdown()
        w.deleteLater()


def test_load_demo_writes_opens_and_registers(qapp, demo_dir, monkeypatch):
    """``--demo``: the demo is written on a worker (here copied from the session's demo to save
    time), opened, and registered into the requested target; busy until all of it is done."""
    import plantreg_gui.core.synthetic as synthetic
    import plantreg_gui.models.registration as session_module
    from plantreg_gui.gui.registration.workspace import RegistrationWorkspace

    calls = []

    def fake_write_demo(folder, progress=None, **kw):
        calls.append(Path(folder))
        shutil.copytree(demo_dir, folder)
        return {"rig": Path(folder) / "rig.json", "recording": Path(folder) / "recording"}

    monkeypatch.setattr(synthetic, "write_demo", fake_write_demo)
    monkeypatch.setattr(session_module, "DEMO_IN_PROCESS", False)  # the fake lives in this process
    w = RegistrationWorkspace()
    w.show()
    try:
        w.load_demo(target="thermal")
        w.set_view("masks")
        assert w.is_busy()
        _wait(qapp, lambda: not w.is_busy())
        assert len(calls) == 1
        assert w.result is not None and w.result.target == "thermal"
        assert w.current_view() == "masks" and w.masks_view.view.displayed().shape == (480, 640, 3)
        folder = calls[0]
        # the demo folder is deleted on close: the export is not proposed inside it
        assert w.default_export_folder() == Path.home() / "plantreg-demo-registered-thermal"
    finally:
        w.shutdown()
        w.deleteLater()
    assert not folder.exists()  # the temporary demo is removed on shutdown


def test_dropping_a_demo_folder_opens_rig_and_recording(qapp, demo_dir):
    from PySide6.QtCore import QMimeData, QPointF, Qt, QUrl
    from PySide6.QtGui import QDropEvent

    from plantreg_gui.gui.registration.workspace import RegistrationWorkspace

    w = RegistrationWorkspace()
    w.show()
    try:
        mime = QMimeData()
        mime.setUrls([QUrl.fromLocalFile(str(demo_dir))])
        ev = QDropEvent(QPointF(10, 10), Qt.DropAction.CopyAction, mime, Qt.MouseButton.NoButton,
                        Qt.KeyboardModifier.NoModifier)
        w.dropEvent(ev)
        _wait(qapp, lambda: not w.is_busy())
        assert w.rig_path == demo_dir / "rig.json" and w.recording_path == demo_dir / "recording"
        assert set(w.raw_grid.views) == {"depth", "ir", "rgb", "thermal", "hyperspectral"}
        assert w.register_button.isEnabled() and w.target_combo.currentText() == "ir"
    finally:
        w.shutdown()
        w.deleteLater()


def test_empty_views_say_why_until_registered(qapp, demo_dir):
    """A view with nothing to show names what is missing (a blank grey pane looks like a fault);
    each note goes away once its content is there."""
    from plantreg_gui.gui.registration.workspace import RegistrationWorkspace

    w = RegistrationWorkspace()
    w.resize(1200, 800)
    w.show()
    notes = w.empty_notes
    try:
        assert set(notes) == {"raw", "side-by-side", "mosaic", "masks", "3d"}
        assert all(not n.isHidden() for n in notes.values())
        assert "Open a rig and a recording" in notes["raw"].text()
        assert w.spectrum.isHidden()  # no empty spectrum plot before a cube is open
        w.open_rig(demo_dir / "rig.json")
        assert "open the recording" in notes["raw"].text() and w.spectrum.isHidden()
        w.open_recording(demo_dir / "recording")
        _wait(qapp, lambda: not w.is_busy())
        assert notes["raw"].isHidden()  # the raw images are there
        assert not w.spectrum.isHidden()  # the recording has a hyperspectral cube
        for key in ("side-by-side", "mosaic", "masks", "3d"):
            assert not notes[key].isHidden()
            assert "press Register" in notes[key].text()
        w.set_view("mosaic")
        assert notes["mosaic"].isVisible() and notes["mosaic"].geometry() == w.mosaic_view.rect()
        w.run_registration("ir")
        assert "Registering into ir" in notes["masks"].text()
        _wait(qapp, lambda: w.result is not None and not w.is_busy())
        assert all(n.isHidden() for n in notes.values())
    finally:
        w.shutdown()
        w.deleteLater()
