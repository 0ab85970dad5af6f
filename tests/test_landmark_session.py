"""The landmark page's Qt-free model (models/landmarks.py) against synthetic truth.

Landmarks are what a careful user clicks on the demo plant (core/synthetic/landmarks.py): the
TRUE surface point projected by the TRUE rig. The start rig is the true one perturbed. A fitted
rig is judged on landmarks it never saw (another random set on the same plant, no click noise).
"""

import json
import math

import numpy as np
import pytest

from plantreg_gui.models.landmarks import LandmarkSession
from plantreg_gui.core.data.landmarks import LandmarkSet
from plantreg_gui.core.data.recording import Recording
from plantreg_gui.core.rigfit.rigfit import RecordingLandmarks, evaluate_landmarks
from plantreg_gui.core.synthetic import demo_rig, make_plant_scene, render_depth
from plantreg_gui.core.synthetic.landmarks import perturb_rig, synthetic_landmarks

CAM = "thermal"


@pytest.fixture(scope="module")
def world():
    rig = demo_rig()
    scene = make_plant_scene(3)
    depth = render_depth(rig, scene)
    rec = Recording(None, depth, {c.name: np.zeros(c.shape, np.float32) for c in rig.cameras})
    return rig, scene, rec


def unseen_px(true_rig, fitted, scene, rec, seed=99):
    """Median residual (px) of ``fitted`` in CAM on 12 noise-free landmarks it was not fitted to."""
    lms = synthetic_landmarks(true_rig, scene, 12, 0.0, np.random.default_rng(seed), sources=[CAM])
    rows, _ = evaluate_landmarks(fitted, [RecordingLandmarks("u", rec.depth_m(true_rig.depth_scale), lms)], [CAM])
    return float(np.median([d["residual_px"] for d in rows]))


def session_for(world, seed=1):
    rig, scene, rec = world
    start = perturb_rig(rig, np.random.default_rng(seed), rotation_deg=3.0, position_m=0.03, focal_rel=0.0,
                        cameras=[CAM])
    return LandmarkSession(start, LandmarkSet(), {"plant": rec})


def click_pairs(s, world, n=12, seed=5, noise=0.5):
    rig, scene, _ = world
    truth = synthetic_landmarks(rig, scene, n, noise, np.random.default_rng(seed), sources=[CAM])
    for lm in truth:
        s.click_depth(lm.depth_uv)
        assert s.pending is not None
        s.click_camera(lm.cameras[CAM])
    return truth


@pytest.mark.parametrize("seed", [1, 2])
def test_clicked_pairs_then_fit_reach_truth(world, seed):
    rig, scene, rec = world
    s = session_for(world, seed)
    s.set_camera(CAM)
    events = []
    s.events.points.connect(lambda: events.append("points"))
    s.events.rig.connect(lambda: events.append("rig"))
    before = unseen_px(rig, s.rig, scene, rec)
    click_pairs(s, world)
    assert len(s.points) == 12 and s.pending is None and events.count("points") == 12
    s.fit()
    after = unseen_px(rig, s.rig, scene, rec)
    assert before > 10.0  # 3 degrees and 3 cm are tens of pixels off
    assert after < 0.5, (before, after)
    assert "rig" in events
    # the table is worst first, every clicked point has a residual near the click noise
    t = s.table()
    res = [r["residual_px"] for r in t]
    assert res == sorted(res, reverse=True) and max(res) < 3.0


def test_undo_redo_restore_points_and_rig(world):
    s = session_for(world)
    s.set_camera(CAM)
    click_pairs(s, world, n=8)
    rig0 = s.rig.to_dict()
    s.fit()
    assert s.rig.to_dict() != rig0
    s.undo()
    assert s.rig.to_dict() == rig0 and len(s.points) == 8
    s.delete_point(3)
    assert len(s.points) == 7
    s.undo()
    assert len(s.points) == 8
    s.undo()  # the 8th click
    assert len(s.points) == 7
    s.redo()
    assert len(s.points) == 8
    s.move_point(0, CAM, [10.25, 20.5])
    assert np.allclose(s.points[0].cameras[CAM], [10.25, 20.5])
    s.undo()
    assert not np.allclose(s.points[0].cameras[CAM], [10.25, 20.5])


def test_nudge_moves_camera_in_its_own_frame_and_fit_converges_back(world):
    rig, scene, rec = world
    s = LandmarkSession(perturb_rig(rig, np.random.default_rng(0), 0.0, 0.0, 0.0, cameras=[CAM]), LandmarkSet(),
                        {"plant": rec})
    s.set_camera(CAM)
    click_pairs(s, world, noise=0.0)
    C0 = s.rig.camera(CAM).center_rig.copy()
    R0 = s.rig.camera(CAM).R_cam_rig.copy()
    s.nudge("translate", 0, 0.01)  # 1 cm along the camera's x axis
    cam = s.rig.camera(CAM)
    assert np.allclose(cam.center_rig - C0, R0[0] * 0.01, atol=1e-9)
    s.nudge("rotate", 1, 2.0)  # 2 degrees about the camera's y axis, centre fixed
    cam = s.rig.camera(CAM)
    assert np.allclose(cam.center_rig - C0, R0[0] * 0.01, atol=1e-9)
    dR = cam.R_cam_rig @ R0.T
    assert math.degrees(math.acos((np.trace(dR) - 1) / 2)) == pytest.approx(2.0, abs=1e-6)
    assert unseen_px(rig, s.rig, scene, rec) > 10.0
    s.fit()
    assert unseen_px(rig, s.rig, scene, rec) < 0.3
    s.undo(), s.undo(), s.undo()  # fit, rotation, translation
    assert np.allclose(s.rig.camera(CAM).center_rig, C0)


def test_pending_needs_depth_click_and_camera_click_adds_to_selected(world):
    s = session_for(world)
    s.set_camera(CAM)
    assert s.click_camera([5, 5]) is None  # nothing pending, nothing selected
    s.add_point([100, 100], {"rgb": [1, 2]})
    assert s.click_camera([7, 8]) == 0 and np.allclose(s.points[0].cameras[CAM], [7, 8])


def test_save_round_trip(world, tmp_path):
    rig, scene, rec = world
    s = session_for(world)
    s.set_camera(CAM)
    click_pairs(s, world, n=8)
    s.fit()
    s.landmarks.base = tmp_path
    p = s.save_landmarks(tmp_path / "lm.json")
    back = LandmarkSet.load(p)
    assert back.count() == 8
    assert np.allclose(back.recordings["plant"][2].cameras[CAM], s.points[2].cameras[CAM])
    r = s.save_rig(tmp_path / "rig.json")
    d = json.loads(r.read_text())
    assert d["calibration"]["landmarks_used"] == 8
    from plantreg_gui.core.camera.rig import Rig

    assert np.allclose(Rig.load(r).camera(CAM).t_cam_rig, s.rig.camera(CAM).t_cam_rig)


def test_a_recording_the_landmarks_file_names_but_is_missing_names_the_landmarks_file(demo_dir, tmp_path):
    """The page opened on a landmarks file whose recording folder is gone: the message names the
    landmarks file (which the user can edit) and the recording it names, not only the folder."""
    from plantreg_gui.core.errors import InputError

    lm = tmp_path / "landmarks.json"
    lm.write_text(json.dumps({"format": "plantreg.landmarks", "version": 1, "recordings": {
        "gone/plant07": {"points": [{"depth_uv": [100, 100], "cameras": {}}]}}}))
    with pytest.raises(InputError) as e:
        LandmarkSession.load(demo_dir / "rig.json", lm)
    msg = str(e.value)
    assert msg.startswith(str(lm)) and "'gone/plant07'" in msg and str(tmp_path / "gone" / "plant07") in msg


def test_nudging_the_depth_camera_is_refused(world):
    from plantreg_gui.core.errors import InputError

    s = session_for(world)
    with pytest.raises(InputError):
        s.nudge("rotate", 0, 1.0, camera=s.rig.depth().name)


def test_undo_keeps_fields_it_does_not_know(world):
    """A landmark's extra fields (written by another tool, kept by the file format) survive an undo
    (before, restoring the undo snapshot dropped everything but depth_uv, cameras and note)."""
    from plantreg_gui.core.data.landmarks import Landmark

    s = session_for(world)
    s.landmarks.recordings["plant"].append(Landmark([10.0, 20.0], {CAM: [30.0, 40.0]}, "tip",
                                                    {"uncertainty_px": 2.5, "by": "annotator A"}))
    s.add_point([50.0, 60.0], {CAM: [70.0, 80.0]})
    s.undo()
    assert len(s.points) == 1 and s.points[0].note == "tip"
    assert s.points[0].extra == {"uncertainty_px": 2.5, "by": "annotator A"}
    assert s.points[0].to_dict()["uncertainty_px"] == 2.5


def test_rigs_saved_by_the_page_keep_the_mixed_pixel_widening(world, tmp_path):
    """Issue 23: a rig fitted on the landmark page, and one nudged after the fit, carry the typed
    calibration record and the mixed-pixel flag's registration uncertainty (0 before: the page's
    method did not read exactly "landmarks")."""
    from plantreg_gui.core.camera.record import CalibrationRecord
    from plantreg_gui.core.camera.rig import Rig
    from plantreg_gui.core.registration.mixed import calibration_residual_px

    s = session_for(world)
    s.set_camera(CAM)
    click_pairs(s, world, n=8)
    s.fit()
    fitted = Rig.load(s.save_rig(tmp_path / "fit.json"))
    rec = CalibrationRecord.of(fitted.extra)
    assert rec.source == "plantreg-gui landmark page" and rec.residual_kind == "landmarks"
    assert rec.per_camera[CAM]["median_px"] > 0
    assert calibration_residual_px(fitted.extra, CAM) == pytest.approx(rec.per_camera[CAM]["median_px"])
    s.nudge("translate", 0, 0.002)
    nudged = Rig.load(s.save_rig(tmp_path / "nudged.json"))
    rec = CalibrationRecord.of(nudged.extra)
    assert rec.method == "manual nudge" and "before_nudge" in rec.details
    # the nudged rig's own residuals (2 mm moved: larger than the fit's)
    assert calibration_residual_px(nudged.extra, CAM) > calibration_residual_px(fitted.extra, CAM) > 0
