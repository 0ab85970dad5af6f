"""The registration workspace on its Qt-free session model (issue 11).

The first tests drive :class:`RegistrationSession` without Qt; the GUI tests get a fresh
workspace each (``workspace`` / ``registered_workspace`` fixtures in conftest.py, which apply one
cached registration of the demo and fail a test that leaves widgets or worker threads behind).
Expected values come from the registration result and the core's rendering, never from the
workspace's own earlier output.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from conftest import workspace_session_outputs


# ---------------------------------------------------------------------- the model, without Qt
def test_session_is_qt_free():
    code = ("import sys; import plantreg_gui.models.registration, plantreg_gui.models.layers; "
            "bad = [m for m in sys.modules if m.startswith(('PySide6', 'shiboken6', 'pyvista'))]; "
            "print(bad); sys.exit(1 if bad else 0)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         cwd=Path(__file__).resolve().parents[1])
    assert out.returncode == 0, out.stdout + out.stderr


def test_session_events_and_readout(demo_registered):
    from plantreg_gui.core.registration.cases import case_label
    from plantreg_gui.models.registration import RegistrationSession

    s = RegistrationSession()
    seen = []
    for name in s.events.NAMES:
        getattr(s.events, name).connect(lambda *a, n=name: seen.append(n))
    loaded, reg = workspace_session_outputs(demo_registered)
    s.apply_loaded(loaded)
    assert "raw" in seen and "source" in seen and s.can_register()
    seen.clear()
    assert s.apply_registered(reg, s.generation)
    assert seen[:2] == ["result", "masks_source"] and "cursor" in seen
    r = s.result
    # the session starts on the source with the most P2 + P3 pixels
    bad = {n: int(np.isin(c, (2, 3, 4)).sum()) for n, c in r.cases.items()}
    assert s.masks_source == max(bad, key=bad.get)
    # the cursor starts on an object pixel and the read-out names the masks source's case there
    _, row, col = s.cursor
    assert np.isfinite(r.points_rig[row, col, 2])
    assert f"{s.masks_source} case: {case_label(r.cases[s.masks_source][row, col])}" in s.readout
    # defect 13: changing the masks source updates the read-out at once (no mouse move needed)
    other = next(n for n in r.cases if n != s.masks_source)
    s.set_masks_source(other)
    assert f"{other} case: {case_label(r.cases[other][row, col])}" in s.readout
    # a stale result (another recording opened meanwhile) is ignored
    assert not s.apply_registered(reg, s.generation - 1)


@pytest.mark.parametrize("reopen", ["recording", "rig", "close"])
def test_opening_other_data_clears_the_readout(demo_registered, reopen):
    """Technician pass 3: a registered plant's read-out (values, case, spectrum) stayed in the
    status line after another recording was opened, as if it were the new plant's."""
    from plantreg_gui.models.registration import RegistrationSession

    s = RegistrationSession()
    loaded, reg = workspace_session_outputs(demo_registered)
    s.apply_loaded(loaded)
    s.apply_registered(reg, s.generation)
    assert s.cursor is not None and "case:" in s.readout
    seen = []
    s.events.cursor.connect(lambda: seen.append((s.cursor, s.readout, s.spectrum)))
    if reopen == "recording":
        s.apply_loaded(workspace_session_outputs(demo_registered)[0])
    elif reopen == "rig":
        s.set_rig(loaded["rig"], Path("other.rig.json"))
    else:
        s.close()
    assert s.result is None and (s.cursor, s.readout, s.spectrum) == (None, "", None)
    assert seen and seen[-1] == (None, "", None)  # the views hear of it


def test_display_settings_rerender_every_place(demo_registered):
    from plantreg_gui.core.display import display
    from plantreg_gui.models.layers import DisplaySettings
    from plantreg_gui.models.registration import RegistrationSession

    s = RegistrationSession()
    loaded, reg = workspace_session_outputs(demo_registered)
    s.apply_loaded(loaded)
    s.apply_registered(reg)
    got = []
    s.events.display.connect(got.append)
    st = DisplaySettings(cmap="magma", percentiles=(5.0, 95.0))
    s.set_display("thermal", st)
    assert got == ["thermal"]
    want = display.to_rgb8(s.result.registered["thermal"], "thermal", cmap="magma", percentiles=(5, 95))
    np.testing.assert_array_equal(s.renders["thermal"], want)
    np.testing.assert_array_equal(s.cloud.colours["thermal"], want.reshape(-1, 3)[s.cloud.pixels])
    raw = next(L for L in s.raw if L.name == "thermal")
    np.testing.assert_array_equal(s.raw_renders["thermal"], display.to_rgb8(raw.data, "thermal", cmap="magma",
                                                                             percentiles=(5, 95)))
    # the cached outputs were not touched (copies per test)
    assert demo_registered["registered"]["renders"]["thermal"] is not s.renders["thermal"]


def test_spectrum_on_an_unmapped_pixel_says_so(demo_registered):
    from plantreg_gui.models.registration import RegistrationSession

    s = RegistrationSession()
    loaded, reg = workspace_session_outputs(demo_registered)
    s.apply_loaded(loaded)
    s.apply_registered(reg)
    hs = s.result.registered["hyperspectral"]
    unmapped = np.argwhere(~np.isfinite(hs).any(axis=2))
    row, col = (int(v) for v in unmapped[0])
    s.hover("target", row, col)
    values, _wl, _title, _unit = s.spectrum
    assert not np.isfinite(values).any()  # the plot is told "nothing here", not left stale


def test_readout_of_a_3_band_cube_gives_its_three_values():
    """A 3-band cube (the real Plant3DImageReg hyperspectral renders, 8-bit) is drawn as RGB, so its
    read-out gives the three values as a colour camera's does (before: "17 @ band 0 (3 bands)");
    a true many-band cube keeps "value @ band k (N bands)"."""
    from plantreg_gui.models.layers import Layer
    from plantreg_gui.models.registration import RegistrationSession

    rng = np.random.default_rng(0)
    hs3 = rng.integers(0, 256, (6, 8, 3), dtype=np.uint8)
    hs3[2, 5] = (17, 45, 120)
    cube = rng.random((6, 8, 50)).astype(np.float32)
    s = RegistrationSession()
    s.raw = [Layer("hyperspectral", "hyperspectral", hs3), Layer("hsi", "hyperspectral", cube)]
    s.layers = list(s.raw)
    s.hover("hyperspectral", 2, 5)
    assert s.readout.endswith("x=5 y=2: (17, 45, 120)")
    s.hover("target", 2, 5)
    assert "hyperspectral: (17, 45, 120)" in s.readout
    assert f"hsi: {cube[2, 5, 25]:.4g} @ band 25 (50 bands)" in s.readout
    # float (registered) 3-band cube: three values, a dash where nothing was mapped
    reg = hs3.astype(np.float32)
    reg[0, 0] = np.nan
    L = Layer("hyperspectral", "hyperspectral", reg)
    assert L.value_text(2, 5) == "(17, 45, 120)" and L.value_text(0, 0) == "—"


def test_layer_titles_say_each_thing_once():
    """A camera named after its modality does not repeat it (the hyperspectral title was cut off
    at the edge of a side-by-side view); other cameras keep their modality, units and bands."""
    from plantreg_gui.models.layers import Layer
    from plantreg_gui.models.registration import RegistrationSession

    s = RegistrationSession()
    cube = Layer("hyperspectral", "hyperspectral", np.zeros((576, 640, 100), np.float32))
    assert s.layer_title(cube) == "hyperspectral  (100 bands, 640x576)"
    ir = Layer("ir", "infrared", np.zeros((576, 640), np.uint16))
    assert s.layer_title(ir) == "ir  (infrared, 640x576)"
    lwir = Layer("lwir", "thermal", np.zeros((480, 640), np.float32), unit="°C")
    assert s.layer_title(lwir) == "lwir  (thermal, °C, 640x480)"


# ---------------------------------------------------------------------- the workspace, fresh per test


@pytest.mark.gui
def test_views_show_the_session(registered_workspace):
    from plantreg_gui.core.display import display

    w = registered_workspace
    r = w.result
    w.set_view("side-by-side")
    for cam in r.registered:
        raw = w.recording.images[cam]
        pca = display.fit_pca(raw) if raw.ndim == 3 and raw.shape[2] > 4 else None  # the raw cube's basis
        expected = display.to_rgb8(r.registered[cam], modality=w.rig.camera(cam).modality, pca=pca)
        np.testing.assert_array_equal(w.sbs_grid.views[cam].view.displayed(), expected)
    w.set_view("masks")
    assert w.masks_view.view.displayed().shape == (*r.shape, 3)
    assert w.masks_view.source.currentText() == w.session.masks_source
    assert all(n.isHidden() for n in w.empty_notes.values())


@pytest.mark.gui
def test_registration_keeps_the_gui_thread_responsive(registered_workspace, qtbot):
    """No GUI-thread gap over 200 ms on an idle machine (issue 11). Tolerance: 0.2 s widened by the
    stretch a control process of the same priority saw over the same interval
    (stall_probe.LoadControl), because on a busy machine the GUI thread waits for a CPU, not for
    our code. (The load average used before lags behind and failed on a busy machine: issue 22.)
    The freezes this guards against took 1-12 s on an idle machine."""
    from stall_probe import LoadControl, StallProbe

    w = registered_workspace
    with LoadControl() as control, StallProbe(trace_after_s=0.12) as probe:
        t0 = time.perf_counter()
        w.run_registration("thermal")  # meshes reused: target rays, casts, sampling, rendering, cloud
        qtbot.waitUntil(lambda: w.result.target == "thermal" and not w.is_busy(), timeout=300_000)
        qtbot.wait(100)  # the views' updates after the result
    secs = time.perf_counter() - t0
    limit = control.allowed(0.2)
    print(f"registration {secs:.2f} s, longest GUI-thread gap {probe.max_gap * 1000:.0f} ms "
          f"(limit {limit * 1000:.0f} ms, control's stretch {control.stretch:.2f})")
    assert probe.ticks >= 0.3 * secs / 0.02 / control.stretch
    assert probe.max_gap < limit, "\n\n".join(probe.traces)


@pytest.mark.gui
def test_progress_text_never_widens_the_window(registered_workspace, qtbot):
    """Defect 2: a long export path in the progress bar widened the window past the screen."""
    w = registered_workspace
    w.resize(1300, 850)
    qtbot.wait(50)
    width = w.width()
    w.progress.show()
    w._progress("Exporting to /" + "very-long-folder-name/" * 20 + "out", 0.5, "writing registered/x.tif")
    qtbot.wait(50)
    assert w.width() == width and w.progress.width() <= w.progress.maximumWidth()
    assert "…" in w.progress.format()
    w.progress.hide()


@pytest.mark.gui
def test_inverted_percentile_limits_are_refused_visibly(registered_workspace, qtbot):
    """Defect 5: 95-5 was accepted silently and drawn as (95, 95.5)."""
    w = registered_workspace
    c = w.controls
    c.layer.setCurrentText("thermal")
    c.hi.setValue(5.0)  # (1, 5): still valid, applied
    qtbot.waitUntil(lambda: w.session.settings_for("thermal").percentiles == (1.0, 5.0))
    qtbot.wait(100)
    shown = w.sbs_grid.views["thermal"].view.displayed().copy()
    c.lo.setValue(95.0)  # (95, 5): inverted
    qtbot.wait(200)  # past the 80 ms throttle
    assert w.session.settings_for("thermal").percentiles == (1.0, 5.0)  # not bent into (95, 95.5)
    np.testing.assert_array_equal(w.sbs_grid.views["thermal"].view.displayed(), shown)
    assert c.limits_note.isVisible()
    c.hi.setValue(99.0)
    c.lo.setValue(2.0)
    qtbot.waitUntil(lambda: w.session.settings_for("thermal").percentiles == (2.0, 99.0))
    assert not c.limits_note.isVisible()


@pytest.mark.gui
def test_mosaic_tile_above_the_slider_range_stays(registered_workspace):
    """Defect 6: typing 1000 px snapped back to 400 (the slider's maximum)."""
    m = registered_workspace.mosaic_view
    m.tile.setValue(1000)
    assert m.tile.value() == 1000 and m.tile_slider.value() == m.tile_slider.maximum()
    m.tile_slider.setValue(32)
    assert m.tile.value() == 32


@pytest.mark.gui
def test_exported_mosaic_is_the_screens(registered_workspace, qtbot, tmp_path):
    """Defect 11: the exported mosaic.png used another tile size than the screen."""
    import cv2

    w = registered_workspace
    w.set_view("mosaic")
    m = w.mosaic_view
    m.set_mode("mosaic")
    m.tile.setValue(37)
    shown = m.view.displayed()
    assert w.export(tmp_path / "out", ["mosaic"])
    qtbot.waitUntil(lambda: not w.is_busy(), timeout=120_000)
    png = cv2.cvtColor(cv2.imread(str(tmp_path / "out" / "mosaic.png")), cv2.COLOR_BGR2RGB)
    np.testing.assert_array_equal(png, shown)


@pytest.mark.gui
def test_demo_is_not_remembered_in_open_recent(workspace, demo_registered):
    """Defect 12: Load demo put temporary paths into Open recent, which failed later."""
    loaded, _ = workspace_session_outputs(demo_registered)
    workspace._loaded(dict(loaded, demo=True))
    assert workspace.recent() == []
    assert workspace.default_export_folder().parent == Path.home()
    workspace._loaded(loaded)  # a real recording is remembered
    assert any(e.startswith("pair:") for e in workspace.recent())  # with its rig: the pair


@pytest.mark.gui
def test_rig_file_errors_say_what_is_wrong(workspace, tmp_path, demo_dir):
    """Defect 16: a folder picked as rig said "rig file not found"; any JSON said "the rig has no cameras"."""
    from plantreg_gui.core.errors import InputError

    with pytest.raises(InputError, match="is a folder, not a rig file"):
        workspace.open_rig(tmp_path)
    other = tmp_path / "notes.json"
    other.write_text(json.dumps({"title": "my plant", "date": "2024-05-01"}))
    with pytest.raises(InputError, match="not a rig file"):
        workspace.open_rig(other)
    with pytest.raises(InputError, match="not a rig file .a recording manifest"):
        workspace.open_rig(demo_dir / "recording" / "recording.json")
    assert workspace.rig is None


@pytest.mark.gui
def test_opening_a_rig_over_a_plant3d_plant_says_what_next(workspace, qtbot, shared_data, demo_dir):
    """Defect 4: opening a rig while a Plant3DImageReg plant was shown lost the plant name, left
    Register disabled and said nothing."""
    folder = shared_data / "plant3dimagereg"
    workspace.open_plant3d(folder, "03areca_palm")
    qtbot.waitUntil(lambda: not workspace.is_busy(), timeout=120_000)
    assert workspace.plant is not None
    workspace.open_rig(demo_dir / "rig.json")
    assert workspace.plant is None and workspace.rig is not None
    assert "rig: rig.json" in workspace.source_label.text()
    note = workspace.empty_notes["raw"]
    assert not note.isHidden() and "open the recording" in note.text()
    assert not workspace.banner.isVisible()


@pytest.mark.gui
def test_screenshot_with_an_unknown_target_fails_loudly(demo_dir, tmp_path):
    """Defect 7: ``--screenshot`` with an unknown ``--target`` exited 0 and printed nothing."""
    env = dict(os.environ, QT_QPA_PLATFORM="offscreen")
    out = subprocess.run([sys.executable, "-m", "plantreg_gui.gui.app", "--rig", str(demo_dir / "rig.json"),
                          "--recording", str(demo_dir / "recording"), "--target", "nosuch",
                          "--screenshot", str(tmp_path / "s.png"), "--timeout", "120"],
                         capture_output=True, text=True, env=env, timeout=300)
    assert out.returncode != 0
    assert "unknown target camera 'nosuch'" in out.stderr


@pytest.mark.gui
def test_screenshot_of_the_3d_view_exits_without_a_traceback(demo_dir, tmp_path):
    """``--view 3d --screenshot`` ended the event loop without closing the window, so at exit
    pyvistaqt closed a plotter whose render timer Qt had already deleted and printed a traceback
    (3 of 4 runs on the real philodendron). The window is now closed after the loop: clean exit."""
    shot = tmp_path / "s.png"
    out = subprocess.run([sys.executable, "-m", "plantreg_gui.gui.app", "--rig", str(demo_dir / "rig.json"),
                          "--recording", str(demo_dir / "recording"), "--target", "ir", "--view", "3d",
                          "--screenshot", str(shot), "--timeout", "240", "--size", "900x600"],
                         capture_output=True, text=True, env=dict(os.environ), timeout=400)
    assert out.returncode == 0, out.stderr
    assert shot.stat().st_size > 10_000
    assert "Traceback" not in out.stderr and "Error" not in out.stderr, out.stderr


def test_hyperspectral_false_colour_is_the_same_raw_and_registered(demo_registered):
    """Defect 10: the PCA false colour was fitted separately on the raw and the registered cube, so
    one leaf had two colours. Both now use the raw cube's basis: a registered pixel has the colour
    of the raw pixel it was sampled from."""
    from plantreg_gui.core.display import display
    from plantreg_gui.models.registration import RegistrationSession

    s = RegistrationSession()
    loaded, reg = workspace_session_outputs(demo_registered)
    s.apply_loaded(loaded)
    s.apply_registered(reg)
    raw = loaded["recording"].images["hyperspectral"]
    reg_cube = s.result.registered["hyperspectral"]
    basis = display.fit_pca(raw)
    np.testing.assert_array_equal(s.renders["hyperspectral"], display.pca_false_colour(reg_cube, basis=basis))
    uv = s.result.source_uv["hyperspectral"]
    ok = np.isfinite(reg_cube).all(axis=2) & np.isfinite(uv).all(axis=2)
    u = np.rint(uv[ok][:, 0]).astype(int).clip(0, raw.shape[1] - 1)
    v = np.rint(uv[ok][:, 1]).astype(int).clip(0, raw.shape[0] - 1)
    raw_rgb = s.raw_renders["hyperspectral"][v, u].astype(int)
    reg_rgb = s.renders["hyperspectral"][ok].astype(int)
    assert ok.sum() > 1000
    # same spectrum, same colour: up to interpolation between neighbouring raw pixels
    assert np.median(np.abs(raw_rgb - reg_rgb)) <= 12


@pytest.mark.gui
def test_registration_parameters_in_the_gui(registered_workspace):
    w = registered_workspace
    s = w.session
    assert s.registrar is not None
    w.params_panel.edge.setValue(25.0)
    w.params_panel.occlusion.setValue(5.0)
    assert s.params.edge_angle_deg == 25.0 and s.params.occlusion_tol_m == pytest.approx(0.005)
    assert s.registrar is None  # the meshes are rebuilt with the new edge angle at the next Register
    assert "Register" in w.params_panel.note.text()


@pytest.mark.gui
def test_display_settings_are_remembered(registered_workspace, qtbot):
    from plantreg_gui.models.layers import DisplaySettings
    from plantreg_gui.gui.registration.workspace import RegistrationWorkspace

    w = registered_workspace
    w.controls.apply("thermal", DisplaySettings("magma", (10.0, 90.0)))
    other = RegistrationWorkspace()  # same QSettings as the fixture's workspace
    try:
        assert other.remembered_display()["thermal"] == DisplaySettings("magma", (10.0, 90.0))
        assert other._job_settings()["thermal"].cmap == "magma"
    finally:
        other.shutdown()
        other.deleteLater()


@pytest.mark.gui
def test_colour_bars_give_the_limits_in_units(registered_workspace, qtbot):
    from plantreg_gui.core.display import display
    from plantreg_gui.models.layers import DisplaySettings

    w = registered_workspace
    r = w.result
    bar = w.sbs_grid.views["thermal"].bar
    assert not bar.isHidden() and bar.cmap == "RdBu_r"
    np.testing.assert_allclose(bar.limits, display.auto_limits(r.registered["thermal"], (1, 99)))
    assert bar.hi.text().endswith("°C")
    w.controls.apply("thermal", DisplaySettings("magma", (5.0, 95.0)))
    assert bar.cmap == "magma"
    np.testing.assert_allclose(bar.limits, display.auto_limits(r.registered["thermal"], (5, 95)))
    assert w.sbs_grid.views["rgb"].bar.isHidden()  # a colour image has no colour bar
    assert not w.raw_grid.views["thermal"].bar.isHidden()


@pytest.mark.gui
def test_mixed_edge_pixels_are_a_mask_layer(registered_workspace):
    """The result's mixed-pixel flags (per source) are offered in the masks view and drawn where
    they are; a source without them offers nothing extra."""
    w = registered_workspace
    r = w.result
    src = next((n for n, m in (getattr(r, "mixed", None) or {}).items() if m is not None and m.any()), None)
    if src is None:
        pytest.skip("this registration flags no mixed pixels (core without mixed-pixel flags)")
    w.session.set_masks_source(src)
    names = [n for n, _m, _what in w.session.mask_layers()]
    assert "mixed edge pixels" in names
    mv = w.masks_view
    w.set_view("masks")
    mv.show_cases.setChecked(False)
    mv.show_areas.setChecked(False)
    mv.opacity.setValue(100)
    cb, mask = mv.extra["mixed edge pixels"]
    np.testing.assert_array_equal(mask, r.mixed[src])
    cb.setChecked(True)
    shown = mv.view.displayed()
    assert np.all(shown[r.mixed[src]] == (255, 40, 40))


def test_wizard_review_choices_leave_a_read_only_session_folder_untouched(tmp_path):
    """The wizard's page, exclusions and per-image options are saved in session.json only where
    the folder has write bits (the detection cache's rule): a folder the user made read-only is
    not changed by looking at it, also when the user is root."""
    import os
    import stat

    from plantreg_gui.core.calibration import Board, Session
    from plantreg_gui.core.calibration.detect import DetectOptions
    from plantreg_gui.models.calibration import WizardModel

    folder = tmp_path / "session"
    s = Session.create(folder, Board("chessboard", 9, 6, 0.03), {"rgb": "rgb", "thermal": "thermal"})
    before = (folder / "session.json").read_bytes()
    mode = folder.stat().st_mode
    os.chmod(folder, mode & ~(stat.S_IWUSR | stat.S_IWGRP | stat.S_IWOTH))
    try:
        m = WizardModel()
        m.set_session(Session.load(folder))
        m.set_wizard_page(4)
        m.set_excluded_many({("pose_01", "rgb")}, True)
        m.set_options(("pose_01", "thermal"), DetectOptions(invert=False, enhance=True))
        assert (folder / "session.json").read_bytes() == before
        assert m.excluded == {("pose_01", "rgb")}  # the choices hold for this run
    finally:
        os.chmod(folder, mode)
    # a writable session keeps them, so that it reopens where it was left
    m = WizardModel()
    m.set_session(Session.load(folder))
    m.set_wizard_page(4)
    m.set_excluded_many({("pose_01", "rgb")}, True)
    review = Session.load(folder).review
    assert review["wizard_page"] == 4 and review["excluded"] == ["pose_01:rgb"]


def test_a_region_is_not_carried_onto_another_target(demo_registered):
    """Technician pass 3: a region drawn on the registration into ir was kept, in pixels, when
    registering into thermal (another camera's grid): its statistics described another part of
    the plant. A new result on the same grid (other parameters) keeps the region."""
    import dataclasses

    from plantreg_gui.models.registration import RegistrationSession, mask_of

    s = RegistrationSession()
    loaded, reg = workspace_session_outputs(demo_registered)
    s.apply_loaded(loaded)
    s.apply_registered(reg, s.generation)
    h, w = s.result.shape
    s.set_region("rect", (w * 0.3, h * 0.3, w * 0.5, h * 0.5))
    assert s.region_stats is not None and s.region_stats.pixels == mask_of(s.result.shape, s.region).sum()
    again = dict(workspace_session_outputs(demo_registered)[1])
    s.apply_registered(again, s.generation)  # same target and size: kept, statistics anew
    assert s.region is not None and s.region_stats is not None and not s.region_note
    other = dict(workspace_session_outputs(demo_registered)[1])
    other["result"] = dataclasses.replace(other["result"], target="thermal")
    seen = []
    s.events.region.connect(lambda: seen.append(s.region_note))
    s.apply_registered(other, s.generation)
    assert s.region is None and s.region_stats is None
    assert "drawn on ir" in s.region_note and "thermal" in s.region_note and seen[-1] == s.region_note
    s.set_region("rect", (1, 1, 5, 5))  # a region drawn on the new grid belongs to it
    assert s.region_grid == ("thermal", (h, w)) and not s.region_note


def test_wrong_folders_are_named_for_what_they_are(demo_dir, tmp_path):
    """Technician pass 3: a calibration session dropped on the workspace was "not a rig file, a
    recording folder or the data set"; an image picked as a session was "session folder not found"."""
    from plantreg_gui.core.calibration.session import Session
    from plantreg_gui.core.errors import InputError
    from plantreg_gui.models.registration import kind_of_path

    with pytest.raises(InputError, match="a calibration session, not a recording: open it in the Calibration tab"):
        kind_of_path(demo_dir / "calibration")
    img = tmp_path / "left.png"
    img.write_bytes(b"\x89PNG\r\n\x1a\n")
    with pytest.raises(InputError, match="is a file, not a session folder"):
        Session.load(img)
    with pytest.raises(InputError, match="session folder not found"):
        Session.load(tmp_path / "missing")
