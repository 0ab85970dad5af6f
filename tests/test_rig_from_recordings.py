"""Issue 23: a rig for someone with only recordings -- `plantreg rig create`, partial fits, honest
quality (refusals, leave-one-landmark-out), landmarks on valid depth, one calibration record.

Ground truth: the synthetic demo rig and its plants (known poses and surfaces), the Azure Kinect
SDK's own mode-specific intrinsics for a published device, the real plants' shipped start rig."""

import json

import numpy as np
import pytest

from plantreg_gui import cli
from plantreg_gui.core.camera.record import CalibrationRecord, landmark_record
from plantreg_gui.core.camera.rig import Rig
from plantreg_gui.core.data.landmarks import Landmark, LandmarkSet
from plantreg_gui.core.data.recording import Recording
from plantreg_gui.core.errors import InputError
from plantreg_gui.core.registration.mixed import calibration_residual_px
from plantreg_gui.core.rigfit.rigfit import (
    RecordingLandmarks, depth_jump, fit_rig, format_report, keep_not_worse, landmark_depth,
)
from plantreg_gui.core.rigfit.start import read_kinect_depth_calibration
from plantreg_gui.core.synthetic import demo_rig, make_plant_scene, render_depth
from plantreg_gui.core.synthetic.landmarks import perturb_rig, synthetic_landmarks

# panispani/3DReconstruct calib.md: one device's raw (normalised, 1024x1024) depth parameters and
# what the Azure Kinect SDK's k4a_calibration_t reports for NFOV unbinned (640x576)
RAW = [0.5122697949409485, 0.49451231956481934, 0.4921168386936188, 0.4921667277812958, 3.1305770874023438,
       2.324939012527466, 0.1304156482219696, 3.458651542663574, 3.350114583969116, 0.6629416346549988, 0, 0,
       -0.0000511557373101823, 0.00008132171933539212]
SDK_NFOV = dict(cx=332.064270, cy=325.880615, fx=503.927643, fy=503.978729, k1=3.130577, k2=2.324939, k3=0.130416,
                k4=3.458652, k5=3.350115, k6=0.662942, p1=0.000081, p2=-0.000051)


def _kinect_json(path):
    path.write_text(json.dumps({"CalibrationInformation": {"Cameras": [
        {"Intrinsics": {"ModelParameterCount": 14, "ModelParameters": RAW,
                        "ModelType": "CALIBRATION_LensDistortionModelBrownConrady"},
         "Location": "CALIBRATION_CameraLocationD0", "Purpose": "CALIBRATION_CameraPurposeDepth",
         "SensorWidth": 1024, "SensorHeight": 1024, "Rt": {"Rotation": [1, 0, 0, 0, 1, 0, 0, 0, 1],
                                                           "Translation": [0, 0, 0]}}]}}))
    return path


def test_kinect_factory_calibration_matches_what_the_sdk_reports(tmp_path):
    K, dist, mode = read_kinect_depth_calibration(_kinect_json(tmp_path / "k4a.json"), 640, 576)
    s = SDK_NFOV
    assert mode == "NFOV_UNBINNED"
    np.testing.assert_allclose([K[0, 2], K[1, 2], K[0, 0], K[1, 1]], [s["cx"], s["cy"], s["fx"], s["fy"]], atol=2e-3)
    np.testing.assert_allclose(dist, [s["k1"], s["k2"], s["p1"], s["p2"], s["k3"], s["k4"], s["k5"], s["k6"]],
                               atol=2e-6)
    with pytest.raises(InputError, match="no Azure Kinect depth mode gives 600x400"):
        read_kinect_depth_calibration(tmp_path / "k4a.json", 600, 400)


def _run(argv, capsys):
    code = cli.main(argv)
    out, err = capsys.readouterr()
    return code, out, err


@pytest.mark.skipif(not (cli.Path(__file__).parents[1] / "resources/plant3dimagereg/rig_nominal.json").exists(),
                    reason="resources missing")
def test_rig_create_turns_cameras_as_the_real_plants_need(tmp_path, capsys):
    """The real plants' start rig (README: hyperspectral seen 90 deg anticlockwise, thermal 90 deg
    clockwise of the infrared) from the command, and the Kinect's factory lens for the infrared."""
    nominal = Rig.load(cli.Path(__file__).parents[1] / "resources/plant3dimagereg/rig_nominal.json")
    out = tmp_path / "start.json"
    code, stdout, err = _run(["rig", "create", str(out), "--depth-camera", "ir",
                              "--camera", f"ir=infrared,640x576,kinect={_kinect_json(tmp_path / 'k.json')},rot=0",
                              "--camera", "thermal=thermal,640x480,hfov=32.7,rot=270,at=-0.03,-0.13,0",
                              "--camera", "hyperspectral=hyperspectral,512x512,hfov=31,rot=90,at=-0.01,-0.12,0",
                              "--roi=-0.425,-0.525,0.30,0.275,0.175,1.15"], capsys)
    assert code == 0, err
    rig = Rig.load(out)
    for c in ("thermal", "hyperspectral"):
        np.testing.assert_allclose(rig.camera(c).R_cam_rig, nominal.camera(c).R_cam_rig, atol=1e-12)
        np.testing.assert_allclose(rig.camera(c).t_cam_rig, nominal.camera(c).t_cam_rig, atol=1e-9)
        np.testing.assert_allclose(rig.camera(c).K, nominal.camera(c).K, atol=0.01)
    assert rig.camera("ir").K[0, 0] == pytest.approx(SDK_NFOV["fx"], abs=2e-3)
    assert "thermal:focal" in err  # the data sheet's field of view: told how to fit the focal length
    # without the device's calibration: the typical lens the real plants' start rig uses (README)
    code, _, err = _run(["rig", "create", str(tmp_path / "t.json"), "--depth-camera", "ir",
                         "--camera", "ir=infrared,640x576,kinect=typical,rot=0"], capsys)
    assert code == 0 and "ir:k1" in err
    typ = Rig.load(tmp_path / "t.json").camera("ir")
    np.testing.assert_allclose(typ.K, nominal.camera("ir").K, atol=1e-9)
    np.testing.assert_allclose(typ.dist, nominal.camera("ir").dist, atol=1e-12)
    # the data sheet's 75 x 65 degrees is not a pinhole: said so
    code, _, err = _run(["rig", "create", str(tmp_path / "b.json"), "--depth-camera", "ir",
                         "--camera", "ir=infrared,640x576,hfov=75,vfov=65,rot=0"], capsys)
    assert code == 0 and "fx 417 but fy 452" in err
    # mistakes: one line, exit 1, nothing written
    for spec, words in (("th=thermal,640x480,hfov=32.7,rot=45", "rot must be 0, 90, 180 or 270"),
                        ("th=thermal,640x480,rot=90", "give exactly one lens"),
                        ("th=warmth,640x480,f=900,rot=90", "unknown modality 'warmth'")):
        code, _, err = _run(["rig", "create", str(tmp_path / "c.json"), "--depth-camera", "ir",
                             "--camera", "ir=infrared,640x576,f=504,rot=0", "--camera", spec], capsys)
        assert code == 1 and words in err and "Traceback" not in err and not (tmp_path / "c.json").exists()
    code, _, err = _run(["rig", "create", str(out), "--depth-camera", "ir", "--camera", "ir=infrared,640x576,f=504,rot=0"],
                        capsys)
    assert code == 1 and "--overwrite" in err


# ---------------------------------------------------------------------------- fits on the demo rig
@pytest.fixture(scope="module")
def demo(tmp_path_factory):
    rig = demo_rig()
    scenes = {s: make_plant_scene(s) for s in (61, 62)}
    depths = {s: Recording(None, render_depth(rig, sc), {}).depth_m(rig.depth_scale) for s, sc in scenes.items()}
    return rig, scenes, depths


def _recs(rig, scenes, depths, rng, n=12):
    return [RecordingLandmarks(f"plant{s}", depths[s], synthetic_landmarks(rig, scenes[s], n, 0.7, rng))
            for s in scenes]


def test_partial_fit_keeps_a_camera_with_too_few_landmarks_at_its_start(demo):
    true, scenes, depths = demo
    rng = np.random.default_rng(5)
    recs = _recs(true, scenes, depths, rng)
    for r in recs:  # thermal seen on 2 landmarks per recording only: 4 < 6
        for lm in r.points[2:]:
            lm.cameras.pop("thermal")
    start = perturb_rig(true, rng)
    res = fit_rig(start, recs, free="rgb:focal,hyperspectral:focal")
    assert np.allclose(res.rig.camera("thermal").R_cam_rig, start.camera("thermal").R_cam_rig)
    assert np.allclose(res.rig.camera("thermal").t_cam_rig, start.camera("thermal").t_cam_rig)
    for c in ("rgb", "hyperspectral"):  # fitted back to the truth from 3 cm off
        assert np.linalg.norm(res.rig.camera(c).center_rig - true.camera(c).center_rig) < 0.015
    assert "thermal" in res.report["not_fitted"]
    assert any("camera 'thermal' not fitted" in w for w in res.warnings)
    assert "NOT FITTED, thermal" in format_report(res.report)
    with pytest.raises(InputError, match="camera 'thermal' has 4 landmark"):  # asked for by name: refused
        fit_rig(start, recs, cameras=["thermal", "rgb"])


def test_outliers_leaving_a_camera_below_its_minimum_refuse_it_by_name(demo):
    true, scenes, depths = demo
    rng = np.random.default_rng(6)
    recs = _recs(true, scenes, depths, rng)
    for r in recs:  # thermal on 4 + 3 landmarks, two of them read 40 px off
        for lm in r.points[4 if r is recs[0] else 3:]:
            lm.cameras.pop("thermal")
    recs[0].points[0].cameras["thermal"] = recs[0].points[0].cameras["thermal"] + [40.0, -10.0]
    recs[1].points[1].cameras["thermal"] = recs[1].points[1].cameras["thermal"] + [-35.0, 25.0]
    with pytest.raises(InputError, match=r"camera 'thermal': 2 of its landmarks are off .* \d left, fewer than the 6"):
        fit_rig(true, recs, loo=False)


def test_leave_one_landmark_out_with_one_recording_says_what_fresh_landmarks_say(demo):
    """One recording: no leave-one-recording-out; each landmark against the rig fitted without it.
    Truth: the fitted rig's error on 40 fresh landmarks of the same plant (new points, new 0.7 px
    click noise): leave-one-landmark-out lies near it and above the fitted residual."""
    from plantreg_gui.core.rigfit.rigfit import evaluate_landmarks

    true, scenes, depths = demo
    rng = np.random.default_rng(7)
    rec = _recs(true, {61: scenes[61]}, {61: depths[61]}, rng, n=14)
    res = fit_rig(perturb_rig(true, rng), rec)
    fresh = _recs(true, {61: scenes[61]}, {61: depths[61]}, np.random.default_rng(70), n=40)
    rows, _ = evaluate_landmarks(res.rig, fresh)
    lolo = res.report["leave_one_landmark_out"]
    for c in ("rgb", "thermal", "hyperspectral"):
        assert lolo[c].get("n", 0) >= 12 and lolo[c]["kind"] == "leave-one-landmark-out", lolo[c]
        truth = np.median([d["residual_px"] for d in rows if d["camera"] == c])
        fitted = res.report["per_camera"][c]["median_px"]
        assert fitted < lolo[c]["median_px"], (c, fitted, truth, lolo[c])
        assert 0.6 * truth < lolo[c]["median_px"] < 1.7 * truth, (c, truth, lolo[c])
    assert "L" in format_report(res.report).split("\n")[2]


def _landmark_file(true, scenes, folder, rng, jumble=False):
    """Recording folders (depth only) of ``scenes`` and ``folder/lm.json`` with 12 landmarks each
    (0.7 px click noise); ``jumble``: every camera pixel replaced by a random one."""
    ls = LandmarkSet(base=folder)
    for s, sc in scenes.items():
        Recording(None, render_depth(true, sc), {}).save(folder / f"p{s}")
        pts = synthetic_landmarks(true, sc, 12, 0.7, rng)
        for lm in pts if jumble else []:
            lm.cameras = {c: np.array([rng.uniform(0, true.camera(c).width - 1), rng.uniform(0, true.camera(c).height - 1)])
                          for c in lm.cameras}
        ls.recordings[f"p{s}"] = pts
    ls.save(folder / "lm.json")


def test_random_landmarks_are_refused(demo, tmp_path, capsys):
    """Every camera pixel replaced by a random one: no rig fits them; exit 1, nothing written."""
    true, scenes, depths = demo
    _landmark_file(true, scenes, tmp_path, np.random.default_rng(8), jumble=True)
    true.save(tmp_path / "start.json")
    out = tmp_path / "fitted.json"
    code, _, err = _run(["fit-rig", "--rig", str(tmp_path / "start.json"), "--landmarks", str(tmp_path / "lm.json"),
                         "--out", str(out)], capsys)
    assert code == 1 and not out.exists() and "Traceback" not in err
    assert ("median landmark residual" in err and "--max-median" in err) or "fewer than the" in err, err


def test_priors_from_the_command_line_reach_the_fit(demo, tmp_path, capsys):
    """A start focal length 15 % short (a data sheet's field of view taken as a pinhole's), focal
    freed: with a loose prior (focal=0.3) the landmarks put it at the truth; a prior that pins it
    (focal=0.005) holds it short of the truth -- the command line's prior is the fit's."""
    true, scenes, depths = demo
    rng = np.random.default_rng(9)
    _landmark_file(true, scenes, tmp_path, rng)
    start = Rig.from_dict(true.to_dict())
    start.camera("thermal").K[:2, :2] *= 0.85
    start.save(tmp_path / "start.json")
    f_true = true.camera("thermal").K[0, 0]
    got = {}
    for prior in ("focal=0.3", "focal=0.005"):
        out = tmp_path / f"fit{len(prior)}.json"
        code, _, err = _run(["fit-rig", "--rig", str(tmp_path / "start.json"), "--landmarks", str(tmp_path / "lm.json"),
                             "--out", str(out), "--free", "thermal:focal", "--prior", prior, "--max-median", "80"],
                            capsys)
        assert code == 0, err
        rig = Rig.load(out)
        got[prior] = rig.camera("thermal").K[0, 0] / f_true - 1
        assert rig.extra["calibration"]["priors"]["focal_rel"] == float(prior.split("=")[1])
    assert abs(got["focal=0.3"]) < 0.01 and got["focal=0.005"] < -0.015, got  # measured 0.15 % and -2.0 %
    code, _, err = _run(["fit-rig", "--rig", str(tmp_path / "start.json"), "--landmarks", str(tmp_path / "lm.json"),
                         "--out", str(tmp_path / "x.json"), "--prior", "zoom=2"], capsys)
    assert code == 1 and "--prior takes KEY=VALUE" in err


# ---------------------------------------------------------------------------- depth under a landmark
def test_a_landmark_reading_the_ground_through_a_notch_is_flagged_and_snapped():
    """A leaf (plane, 0.62-0.68 m) with a notch through which the ground (1.21 m) shows, as the
    grapevine's leaf notch in the issue: the click in the notch reads the ground."""
    H, W = 120, 160
    vv, uu = np.mgrid[0:H, 0:W].astype(float)
    z_leaf = 1.0 / (1 / 0.65 + 0.0004 * (uu - 80) - 0.0003 * (vv - 60))  # a tilted leaf: plane in inverse depth
    depth = z_leaf.copy()
    notch = (np.abs(uu - 80) <= 1.5) & (vv >= 52) & (vv <= 68)  # 3 px wide slit
    depth[notch] = 1.21
    z, _ = landmark_depth(depth, np.array([80.0, 60.0]))
    assert z == pytest.approx(1.21, abs=0.01)  # the robust reading takes the surface under the click
    why, z_snap = depth_jump(depth, np.array([80.0, 60.0]), z, ground_z=1.2)
    assert "ground" in why and "behind" in why
    assert z_snap == pytest.approx(z_leaf[60, 80], abs=0.005)  # onto the leaf at the click
    z_ok, _ = landmark_depth(depth, np.array([40.0, 30.0]))  # on the leaf, away from the notch
    assert depth_jump(depth, np.array([40.0, 30.0]), z_ok, 1.2)[0] == ""


def test_ground_landmark_is_left_out_or_snapped_in_the_fit(demo):
    true, scenes, depths = demo
    rng = np.random.default_rng(10)
    recs = _recs(true, scenes, depths, rng)
    d = recs[0].depth_m.copy()
    uv = recs[0].points[0].depth_uv
    u, v = int(round(uv[0])), int(round(uv[1]))
    z_true = d[v, u]
    d[v - 1:v + 2, u - 1:u + 2] = 1.25  # a 3x3 hole to the ground under the click
    recs[0] = RecordingLandmarks(recs[0].name, d, recs[0].points, snap_depth=False)
    res = fit_rig(true, recs, loo=False)
    assert any(r["index"] == 0 and "behind" in r["reason"] for r in res.report["landmarks_rejected"])
    recs[0].snap_depth = True
    res = fit_rig(true, recs, loo=False)
    (sn,) = res.report["landmarks_snapped"]
    assert sn["snapped_to_m"] == pytest.approx(z_true, abs=0.01)
    assert any(r["index"] == 0 and r["recording"] == recs[0].name and r["depth_m"] == pytest.approx(z_true, abs=0.01)
               for r in res.report["residuals"])


# ---------------------------------------------------------------------------- image stages and the record
def test_a_stage_that_makes_a_camera_worse_is_reverted(demo):
    true, *_ = demo
    moved = perturb_rig(true, np.random.default_rng(11))
    rep = {"thermal": {"start_cost": 10.0, "end_cost": 12.0},
           "rgb": {"start_cost": 10.0, "end_cost": 8.0, "landmarks_px": {"before": {"median_px": 1.0},
                                                                          "after": {"median_px": 2.5}}},
           "hyperspectral": {"start_cost": 10.0, "end_cost": 8.0,
                             "views": {"a": {"landmarks_px": [1.0, 1.2], "landmarks_px_after": [0.9, 1.0]}}}}
    out, warns = keep_not_worse(true, moved, rep, "silhouette fit")
    for c in ("thermal", "rgb"):
        assert np.allclose(out.camera(c).t_cam_rig, true.camera(c).t_cam_rig) and "reverted" in rep[c]
        assert any(w.startswith(f"{c}: silhouette fit made it worse") for w in warns)
    assert np.allclose(out.camera("hyperspectral").t_cam_rig, moved.camera("hyperspectral").t_cam_rig)


@pytest.mark.parametrize("method", ["landmarks", "landmarks+refine", "landmarks+silhouette",
                                    "landmarks+refine+silhouette", "landmarks (plantreg-gui landmark page)",
                                    "manual nudge (plantreg-gui landmark page)"])
def test_every_way_of_fitting_a_rig_keeps_the_mixed_pixel_widening(method):
    """Records as fit-rig (every stage) and the landmark page (fit, nudge) wrote them before the
    record was typed, and as they write them now."""
    per = {"thermal": {"n": 9, "median_px": 2.5, "p90_px": 5.0, "max_px": 6.0}}
    assert calibration_residual_px({"calibration": {"method": method, "per_camera": per}}, "thermal") == 2.5
    rec = landmark_record(method, "test", {"per_camera": per, "leave_one_out": {"per_camera": {
        "thermal": {"median_px": 3.1}}}})
    rig = demo_rig()
    rec.store(rig)
    back = Rig.from_dict(json.loads(json.dumps(rig.to_dict())))
    assert calibration_residual_px(back.extra, "thermal") == pytest.approx(3.1)  # the held-out figure, larger
    assert calibration_residual_px(back.extra, "rgb") == 0.0
    assert CalibrationRecord.of(back.extra).method == method


def test_fit_rig_command_writes_the_typed_record(demo, tmp_path, capsys):
    true, scenes, depths = demo
    rng = np.random.default_rng(12)
    _landmark_file(true, scenes, tmp_path, rng)
    perturb_rig(true, rng).save(tmp_path / "start.json")
    code, stdout, err = _run(["fit-rig", "--rig", str(tmp_path / "start.json"), "--landmarks", str(tmp_path / "lm.json"),
                              "--out", str(tmp_path / "f.json"), "--fit", "thermal,rgb"], capsys)
    assert code == 0, err
    rig = Rig.load(tmp_path / "f.json")
    rec = CalibrationRecord.of(rig.extra)
    assert rec.method == "landmarks" and rec.source == "plantreg fit-rig" and rec.residual_kind == "landmarks"
    assert set(rec.per_camera) == {"thermal", "rgb"}  # --fit: hyperspectral not fitted
    assert np.allclose(rig.camera("hyperspectral").R_cam_rig, Rig.load(tmp_path / "start.json").camera(
        "hyperspectral").R_cam_rig)
    assert calibration_residual_px(rig.extra, "thermal") >= rec.per_camera["thermal"]["median_px"] > 0


REAL = cli.Path(__file__).parents[1] / "resources" / "plant3dimagereg"
# the shipped recordings list files of the data set beside the project (shared/, as in CI)
REAL_DATA = cli.Path(__file__).resolve().parents[2] / "shared" / "data" / "plant3dimagereg"
needs_real = pytest.mark.skipif(not (REAL_DATA / "infra_np").is_dir(),
                                reason=f"the Plant3DImageReg data set is not at {REAL_DATA}")


@needs_real
def test_the_real_grapevine_click_past_a_leaf_edge_is_flagged_and_no_shipped_landmark_is():
    """The issue's case: on the grapevine a click at u = 206.5 reads the ground (1.21 m), one
    pixel right reads the leaf (0.65 m)."""
    from plantreg_gui.core.rigfit.rigfit import load_recording_landmarks

    rig = Rig.load(REAL / "rig.json")
    depth = Recording.load(REAL / "recordings" / "01grapevine", rig).depth_m(rig.depth_scale)
    z, _ = landmark_depth(depth, np.array([206.5, 235.0]))
    assert z == pytest.approx(1.21, abs=0.02)
    why, z_snap = depth_jump(depth, np.array([206.5, 235.0]), z, rig.ground_z)
    assert "ground" in why and z_snap == pytest.approx(landmark_depth(depth, np.array([207.5, 235.0]))[0], abs=0.015)
    z_leaf, _ = landmark_depth(depth, np.array([207.5, 235.0]))
    assert z_leaf < 0.7 and depth_jump(depth, np.array([207.5, 235.0]), z_leaf, rig.ground_z)[0] == ""
    for f in ("landmarks.json", "landmarks_heldout.json"):  # read with care and moved onto the leaf
        for r in load_recording_landmarks(rig, LandmarkSet.load(REAL / f, rig)):
            for lm in r.points:
                zz, _ = landmark_depth(r.depth_m, lm.depth_uv)
                assert depth_jump(r.depth_m, lm.depth_uv, zz, rig.ground_z)[0] == "", (f, r.name, lm.note)


@needs_real
def test_a_data_sheet_pinhole_start_that_would_fold_the_lens_is_refused(tmp_path, capsys):
    """The issue's newcomer start: the depth camera as a 75 x 65 degree pinhole (fx 417; the real
    lens is ~504 with strong distortion), k1 freed: the fit's k1 (-0.36) folds the image -- a rig
    no tool can load. Refused, nothing written; the typical Kinect lens works (README figures)."""
    start = tmp_path / "start.json"
    cams = ["--camera", "thermal=thermal,640x480,hfov=32.7,rot=270",
            "--camera", "hyperspectral=hyperspectral,512x512,hfov=31,rot=90", "--roi=-0.425,-0.525,0.30,0.275,0.175,1.15"]
    assert _run(["rig", "create", str(start), "--depth-camera", "ir",
                 "--camera", "ir=infrared,640x576,hfov=75,vfov=65,rot=0", *cams], capsys)[0] == 0
    out = tmp_path / "fit.json"
    code, _, err = _run(["fit-rig", "--rig", str(start), "--landmarks", str(REAL / "landmarks.json"), "--out", str(out),
                         "--free", "ir:k1", "--quiet"], capsys)
    assert code == 1 and "folds the image" in err and not out.exists()
    assert _run(["rig", "create", str(start), "--overwrite", "--depth-camera", "ir",
                 "--camera", "ir=infrared,640x576,kinect=typical,rot=0", *cams], capsys)[0] == 0
    code, stdout, err = _run(["fit-rig", "--rig", str(start), "--landmarks", str(REAL / "landmarks.json"), "--out",
                              str(out), "--free", "ir:k1", "--quiet"], capsys)
    assert code == 0, err
    rec = CalibrationRecord.of(Rig.load(out).extra)
    # measured 2.61 px fitted / 3.12 leave-one-plant-out (hyperspectral), 2.38 / 4.20 leave-one-landmark-out (thermal)
    assert rec.per_camera["hyperspectral"]["median_px"] < 3.5 and rec.uncertainty_px["thermal"] < 5.0
    assert "start, thermal: start pose from PnP" in stdout
