"""The landmark page shows how the fit takes each landmark's depth (issue 23): on the surface
under the click, snapped onto a nearer surface beside it, or left out -- with a switch for
snapping that means what ``fit-rig --no-snap-depth`` means, kept in the Qt-free session.

Ground truth: the demo rig and a synthetic plant. One landmark is clicked one pixel past a
leaf's edge, where the depth camera sees the ground; the point meant is the leaf's edge, i.e.
the leaf's plane (the triangle beside the click) met by the click's ray. Its camera pixel is
that true point projected by the true rig, so a fit that takes the leaf's depth fits it, one
that takes the ground's does not.
"""

import math
from pathlib import Path

import numpy as np
import pytest

from plantreg_gui.core.camera.rig import Rig
from plantreg_gui.core.data.landmarks import Landmark, LandmarkSet
from plantreg_gui.core.data.recording import Recording
from plantreg_gui.core.rigfit.rigfit import RecordingLandmarks, check_landmark_depth, evaluate_landmarks
from plantreg_gui.core.synthetic import demo_rig, make_plant_scene, render_depth
from plantreg_gui.core.synthetic.landmarks import perturb_rig, synthetic_landmarks
from plantreg_gui.core.synthetic.scene import MAT_GROUND, MAT_LEAF0
from plantreg_gui.models.landmarks import LandmarkSession

CAM = "thermal"


def edge_landmark(rig, scene, depth, rng):
    """A click on the ground one pixel past a leaf's edge (a third of its 7x7 core on the leaf).

    Returns the landmark (its thermal pixel: the true edge point projected) and the true depth
    (m, along the depth camera's axis) of the leaf's plane at the click."""
    cam = rig.depth()
    px = cam.pixel_grid()
    o, d = cam.rays_rig(px)
    _t, prim, _b = scene.cast(o, d)
    H, W = depth.shape
    prim = prim.reshape(H, W)
    mat = np.where(prim >= 0, scene.material[np.maximum(prim, 0)], -1)
    leaf = mat >= MAT_LEAF0
    cands = []
    for v in range(8, H - 8):
        for u in range(8, W - 8):
            if mat[v, u] != MAT_GROUND or not leaf[v, u + 1] or leaf[v, u - 1]:
                continue  # the ground, the leaf right beside it, open ground on the other side
            if leaf[v - 3:v + 4, u - 3:u + 4].mean() >= 0.3:
                cands.append((u, v))
    assert len(cands) > 20
    u, v = cands[rng.integers(len(cands))]
    # the leaf's plane (the triangle of the pixel beside the click) met by the click's ray
    tri = scene.vertices[scene.triangles[prim[v, u + 1]]]
    n = np.cross(tri[1] - tri[0], tri[2] - tri[0])
    oo, dd = cam.rays_rig(np.array([[u, v]], float))
    oo, dd = np.asarray(oo, float).reshape(3), dd.reshape(3)
    P = oo + dd * (n @ (tri[0] - oo)) / (n @ dd)
    z_true = float(cam.to_cam(P[None])[0, 2])
    uv_cam, _ = rig.camera(CAM).project(P[None])
    return Landmark(np.array([u, v], float), {CAM: uv_cam[0]}, note="just past a leaf's edge"), z_true


@pytest.fixture(scope="module", params=[3, 0], ids=["plant3", "plant0"])
def world(request):
    rig = demo_rig()
    scene = make_plant_scene(request.param)
    rec = Recording(None, render_depth(rig, scene), {c.name: np.zeros(c.shape, np.float32) for c in rig.cameras})
    return rig, scene, rec


def session_with_edge(world, seed=5):
    """12 careful clicks (0.3 px noise) and the edge click last; the start rig's thermal camera off."""
    rig, scene, rec = world
    rng = np.random.default_rng(seed)
    depth = rec.depth_m(rig.depth_scale)
    truth = synthetic_landmarks(rig, scene, 12, 0.3, rng, sources=[CAM])
    edge, z_true = edge_landmark(rig, scene, depth, rng)
    start = perturb_rig(rig, rng, rotation_deg=2.0, position_m=0.02, focal_rel=0.0, cameras=[CAM])
    s = LandmarkSession(start, LandmarkSet(), {"plant": rec})
    s.set_camera(CAM)
    for lm in truth + [edge]:
        s.add_point(lm.depth_uv, lm.cameras, lm.note)
    return s, truth, z_true


def test_session_flags_the_edge_landmark_and_the_switch_means_what_no_snap_depth_means(world):
    rig, scene, rec = world
    s, truth, z_true = session_with_edge(world)
    depth = rec.depth_m(rig.depth_scale)
    edge = len(truth)
    assert s.snap_depth  # as fit-rig without --no-snap-depth
    checks = s.depth_checks()
    # the careful clicks: on their surface, at the true point's depth
    for i, lm in enumerate(truth):
        P = np.array([float(x) for x in lm.note.split("[")[1].split("]")[0].split(",")])
        assert checks[i].status == "ok" and checks[i].z_m == pytest.approx(rig.depth().to_cam(P[None])[0, 2], abs=0.005)
    # the edge click read the ground and is put onto the leaf beside it, by the true amount
    u, v = (int(a) for a in s.points[edge].depth_uv)
    c = checks[edge]
    assert c.status == "snapped" and "behind" in c.reason
    assert c.read_m == pytest.approx(depth[v, u], abs=0.01) and depth[v, u] > rig.ground_z - 0.1
    assert c.z_m == pytest.approx(z_true, abs=0.01)
    assert c.snapped_mm == pytest.approx(1000 * (depth[v, u] - z_true), abs=10)
    row = next(r for r in s.table() if r["index"] == edge)
    assert row["depth"] == c and row["residual_px"] is not None
    uv = s.points[edge].depth_uv  # the CLI's switch and the page's: one decision either way round
    assert check_landmark_depth(depth, uv, rig.ground_z, snap=False).snapping(True) == c
    assert check_landmark_depth(depth, uv, rig.ground_z, snap=True).snapping(False) == \
        check_landmark_depth(depth, uv, rig.ground_z, snap=False)
    # the rig's prediction uses the depth the fit uses: the true rig puts the point where it was meant
    s_true = LandmarkSession(rig, LandmarkSet(), {"plant": rec})
    s_true.add_point(s.points[edge].depth_uv, s.points[edge].cameras)
    s_true.set_camera(CAM)
    assert np.linalg.norm(s_true.predicted(0) - s.points[edge].cameras[CAM]) < 1.0

    # the page's fit: the snapped landmark in, fitted as the truth says
    res = s.fit()
    (sn,) = res.report["landmarks_snapped"]
    assert sn["index"] == edge and sn["snapped_to_m"] == c.z_m  # one decision, the page's and the fit's
    fitted = {d["index"]: d["residual_px"] for d in res.report["residuals"]}
    assert fitted[edge] < 2.0, fitted
    assert _unseen_px(rig, s.rig, scene, rec) < 1.0

    # switched off: the same landmark is left out, in the table and in the fit
    seen = []
    s.events.options.connect(lambda: seen.append("options"))
    s.events.points.connect(lambda: seen.append("points"))
    s.set_snap_depth(False)
    assert seen == ["options", "points"]
    c2 = s.depth_checks()[edge]
    assert c2.status == "left out" and math.isnan(c2.z_m) and "--no-snap-depth" in c2.reason
    assert all(s.depth_checks()[i].status == "ok" for i in range(edge))
    assert edge not in s.residuals() and s.predicted(edge) is None
    res = s.fit()
    assert [d["index"] for d in res.report["landmarks_rejected"]] == [edge]
    assert res.report["landmarks_used"] == edge and not res.report["landmarks_snapped"]


def _unseen_px(true_rig, fitted, scene, rec):
    lms = synthetic_landmarks(true_rig, scene, 12, 0.0, np.random.default_rng(99), sources=[CAM])
    rows, _ = evaluate_landmarks(fitted, [RecordingLandmarks("u", rec.depth_m(true_rig.depth_scale), lms)], [CAM])
    return float(np.median([d["residual_px"] for d in rows]))


def test_page_shows_the_depth_flag_and_its_switch_follows_the_session(qtbot, world):
    from plantreg_gui.gui.landmarks.page import TABLE_COLUMNS, LandmarkPage

    s, truth, z_true = session_with_edge(world, seed=6)
    edge = len(truth)
    page = LandmarkPage()
    qtbot.addWidget(page)
    page.resize(1500, 900)
    page.show()
    qtbot.waitExposed(page)
    page.set_session(s)
    try:
        col = TABLE_COLUMNS.index("depth")

        def cell(index):
            t = page.table
            r = next(r for r in range(t.rowCount()) if int(t.item(r, 0).text()) == index)
            return t.item(r, col)

        assert page.snap_depth.isChecked()
        c = cell(edge)
        mm = 1000 * (s.depth_check(edge).read_m - z_true)
        got = float(c.text().split("snapped ")[1].split(" mm")[0])
        assert got == pytest.approx(mm, abs=10) and "behind" in c.toolTip()
        assert cell(0).text().endswith(" m") and not cell(0).toolTip()
        edge_marker = next(m for m in page.left.markers if m.index == edge)
        assert "snapped" in edge_marker.label
        s.select(edge)  # selected (on the image or in the table): the hint says why, the table shows its row
        assert "behind" in page.hint.text() and f"snapped to {s.depth_check(edge).z_m:.3f} m" in page.hint.text()
        assert int(page.table.selectedItems()[0].text()) == edge
        s.select(None)

        page.snap_depth.click()  # the view's switch sets the model
        assert not s.snap_depth
        assert cell(edge).text().startswith("left out") and "--no-snap-depth" in cell(edge).toolTip()
        assert page.table.item(next(r for r in range(page.table.rowCount())
                                    if int(page.table.item(r, 0).text()) == edge), 1).text() == "—"
        with qtbot.waitSignal(page.fit_done, timeout=300_000):
            page.fit_button.click()
        assert [d["index"] for d in s.report["landmarks_rejected"]] == [edge]
        assert "not used" in page.report_text.toPlainText()

        s.set_snap_depth(True)  # the model's change shows in the view
        assert page.snap_depth.isChecked() and "snapped" in cell(edge).text()
    finally:
        qtbot.waitUntil(lambda: not page.is_busy(), timeout=300_000)
        page.shutdown()


# ---------------------------------------------------------------------------- corners the ToF stops short of
def _corner_scene(gap_px):
    """A tilted leaf (plane in inverse depth, 0.6-0.7 m) filling u < 80 over the ground (1.21 m),
    with no depth in a band of ``gap_px`` px beyond its edge (the ToF's mixed pixels at an
    occluding edge). Returns the depth map and the leaf's true depth at any pixel."""
    H, W = 120, 160
    vv, uu = np.mgrid[0:H, 0:W].astype(float)
    leaf = 1.0 / (1 / 0.65 + 0.0005 * (uu - 80) - 0.0004 * (vv - 60))
    depth = np.where(uu < 80, leaf, 1.21)
    depth[(uu >= 80) & (uu < 80 + gap_px)] = np.nan
    return depth, leaf


@pytest.mark.parametrize("gap_px", [2, 4, 6])
def test_a_ground_click_the_valid_leaf_depth_stops_short_of_is_snapped_onto_the_leaf(gap_px):
    """The silhouette-corner click of a user who has not moved it inward by hand: it reads the
    ground, the leaf's valid depth ends ``gap_px`` + 1 px away (too few leaf pixels in the 7x7
    core for the core rule) -- flagged and put on the leaf's plane; a ground click well away from
    any leaf is left alone."""
    depth, leaf = _corner_scene(gap_px)
    uv = np.array([80.0 + gap_px, 60.0])  # the first ground pixel past the band
    c = check_landmark_depth(depth, uv, ground_z=1.2)
    assert c.read_m == pytest.approx(1.21, abs=0.005)
    assert c.status == "snapped" and "ground" in c.reason
    assert c.z_m == pytest.approx(leaf[60, int(uv[0])], abs=0.005)  # the leaf's plane extended to the click
    far = check_landmark_depth(depth, np.array([80.0 + gap_px + 12, 60.0]), ground_z=1.2)
    assert far.status == "ok" and far.z_m == pytest.approx(1.21, abs=0.005)


REAL = Path(__file__).resolve().parents[1] / "resources" / "plant3dimagereg"
REAL_DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "plant3dimagereg"


@pytest.mark.skipif(not (REAL_DATA / "infra_np").is_dir(), reason=f"the Plant3DImageReg data set is not at {REAL_DATA}")
def test_real_clicks_as_read_that_hit_the_ground_are_snapped_to_the_hand_validated_depth():
    """The 26 fitted pairs of the real plants as they were read (``feature_ir``: the mean of two eye
    readings, before finalize.py moved each onto valid depth by hand, ``ir``). Truth: the depth
    of the hand-moved point, which finalize.py checked lies on the plant and agrees with the leaf
    further in. No click may take the ground's depth; each one that read the ground lands within
    2 cm of that depth (the hand step itself moved 2.5-6.5 px along a tilted leaf)."""
    import json

    from plantreg_gui.core.rigfit.rigfit import landmark_depth

    rig = Rig.load(REAL / "rig_nominal.json")
    ann = json.loads((REAL / "landmark_scripts" / "annotations.json").read_text())
    depth = {}
    n_ground = 0
    for key, items in ann.items():
        plant = key.split("/")[0]
        if plant not in depth:
            depth[plant] = Recording.load(REAL / "recordings" / plant, rig).depth_m(rig.depth_scale)
        for it in items:
            if it.get("held_out"):
                continue
            c = check_landmark_depth(depth[plant], np.array(it["feature_ir"], float), rig.ground_z)
            if c.status == "no depth":  # named and left out of the fit
                continue
            assert c.z_m < rig.ground_z - 0.2, (key, it["note"], c)
            if c.status == "snapped":
                n_ground += c.read_m > rig.ground_z - 0.05
                z_hand, _ = landmark_depth(depth[plant], np.array(it["ir"], float))
                assert c.z_m == pytest.approx(z_hand, abs=0.02), (key, it["note"])
    assert n_ground >= 12  # measured: 16 of the 23 with depth read the ground


@pytest.mark.parametrize("seed", [0, 31, 44, 60, 70, 71])
def test_no_landmark_on_the_plant_is_flagged(seed):
    """The other side: 40 landmarks on a demo plant (pot, soil, stems, leaves; many near a leaf's
    edge or above a lower leaf) keep the depth of their true point."""
    rig = demo_rig()
    scene = make_plant_scene(seed)
    depth = Recording(None, render_depth(rig, scene), {}).depth_m(rig.depth_scale)
    for lm in synthetic_landmarks(rig, scene, 40, 0.0, np.random.default_rng(seed)):
        P = np.array([float(x) for x in lm.note.split("[")[1].split("]")[0].split(",")])
        c = check_landmark_depth(depth, lm.depth_uv, rig.ground_z)
        assert c.status == "ok" and c.z_m == pytest.approx(rig.depth().to_cam(P[None])[0, 2], abs=0.01), lm.note


@pytest.mark.parametrize("seed", [7, 19])
def test_the_silhouette_fits_landmark_term_takes_the_same_depth_as_the_landmark_fit(world, seed):
    """``--silhouette`` uses landmarks as a term of its fit: an edge click that reads the ground
    must put its 3D point on the leaf (snapped) as the landmark fit does, or leave it out
    with ``--no-snap-depth``; never at the ground's depth (the click's pixel value)."""
    from plantreg_gui.core.rigfit.silhouette import landmark_points

    rig, scene, rec = world
    depth = rec.depth_m(rig.depth_scale)
    edge, z_true = edge_landmark(rig, scene, depth, np.random.default_rng(seed))
    u, v = edge.depth_uv.astype(int)
    assert depth[v, u] - z_true > 0.05  # the click's own pixel reads the ground
    X, ok = landmark_points(rig, depth, edge.depth_uv[None])
    assert ok[0]
    z_used = float(rig.depth().to_cam(X)[0, 2])
    assert z_used == pytest.approx(check_landmark_depth(depth, edge.depth_uv, rig.ground_z).z_m, abs=1e-9)
    assert abs(z_used - z_true) < 0.01  # on the leaf
    _X, ok_off = landmark_points(rig, depth, edge.depth_uv[None], snap=False)
    assert not ok_off[0]


@pytest.mark.parametrize("seed", [3, 41])
def test_the_page_summary_leaves_out_the_landmark_the_fit_set_aside(world, seed):
    """A click paired with the wrong camera pixel (30 px off, known bad by construction) is set
    aside by the robust fit; the page's residual summary of the current rig (shown once the rig
    is nudged) is over the landmarks the fit used, as ``fit-rig`` reports, and says one was set
    aside -- it must not carry the bad pair's 30 px into median and max."""
    rig, scene, rec = world
    rng = np.random.default_rng(seed)
    truth = synthetic_landmarks(rig, scene, 14, 0.3, rng, sources=[CAM])
    start = perturb_rig(rig, rng, rotation_deg=1.0, position_m=0.01, focal_rel=0.0, cameras=[CAM])
    s = LandmarkSession(start, LandmarkSet(), {"plant": rec})
    s.set_camera(CAM)
    bad = 5
    for i, lm in enumerate(truth):
        uv = np.asarray(lm.cameras[CAM], float) + (np.array([30.0, 0.0]) if i == bad else 0.0)
        s.add_point(lm.depth_uv, {CAM: uv}, lm.note)
    res = s.fit()
    assert [d["index"] for d in res.report["residuals"] if d["outlier"]] == [bad]
    assert s.set_aside() == {("plant", bad, CAM)}
    s.nudge("rotate", 0, 0.01)  # the report is no longer of the current rig: the page shows the summary
    summ = s.summary()[CAM]
    assert summ["n"] == len(truth) - 1 and summ["set_aside"] == 1
    assert summ["max_px"] < 5.0  # the truth's clicks: 0.3 px noise plus a 0.01 deg nudge
    # an edited point is no longer the one the fit set aside
    s.points[bad].note = "read again"
    assert s.set_aside() == set() and s.summary()[CAM]["n"] == len(truth)
