"""``plantreg calibrate`` on real multi-camera sets nobody here recorded, against published figures.

* Herrera et al.'s Kinect RGB + external 2784 x 1856 RGB, symmetric 8 x 6 board (reference with
  1-sigma: shared/data/realcal/herrera_kinect_rgb/reference), all 92 images; the figures and why the
  Kinect's fx falls short of the issue's 0.1 % are in docs/calibration.md.
* FLIR Lepton 3.5 (120 x 160 palette) + ZED 2i, hand-held symmetric 4 x 6 foil board, pairs only
  approximately simultaneous, no published reference.

Sessions are built from symlinks in a temporary folder (tests/realcal.py), never in shared/.
"""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from plantreg_gui.cli import main
from plantreg_gui.core.camera.rig import Rig
from realcal import herrera_reference, herrera_rgb_only_reference, herrera_session, lepton_session


def _angle_deg(R: np.ndarray) -> float:
    return float(np.degrees(np.arccos(np.clip((np.trace(R) - 1) / 2, -1, 1))))


@pytest.fixture(scope="module")
def herrera_run(shared_data, tmp_path_factory):
    tmp = tmp_path_factory.mktemp("herrera")
    s = herrera_session(shared_data, tmp / "session")  # all 54 Kinect views, 38 with the external camera
    code = main(["calibrate", str(s), "--out", str(tmp / "rig.json"), "--report", str(tmp / "report.json"), "--quiet"])
    return code, tmp


def test_herrera_symmetric_board_against_the_published_calibration(herrera_run, shared_data):
    """The issue's figures on the full set: the external camera's fx within 0.3 % of the published
    4073.1 px, its pose within 0.1 degree and 1 mm of the published one. The Kinect's fx: the
    issue asks 0.1 % of the published 1059.73 px, which is not met (+0.24 %): the published
    calibration also fits the Kinect's depth images (not in the set), which moved the toolbox's own
    fx from 1062.87 px (its joint fit of the two RGB cameras alone, the same method on the same
    images) to 1059.73 (docs/calibration.md). Against that RGB-only figure: within 0.1 % and 3 of
    our reported sigmas; against the published one within 0.3 %. The Kinect's lens model is on a
    knife edge here: the rational model predicts held-out views as well (0.220 against 0.221 px with
    these folds, 4-5 % better with each of seeds 1-7) and gives fx 1059.9 with the pose 1.4 mm off;
    a change to the cross-validation that flips it fails this test on the pose."""
    code, tmp = herrera_run
    assert code == 0
    ref, rgb_only = herrera_reference(shared_data), herrera_rgb_only_reference()
    rig = Rig.load(tmp / "rig.json")
    kin, ext = rig.camera("kinect"), rig.camera("external")
    report = json.loads((tmp / "report.json").read_text())
    u = report["uncertainty"]
    assert abs(ext.K[0, 0] / ref["K_external"][0, 0] - 1) < 0.003
    assert abs(kin.K[0, 0] / rgb_only["K_kinect"][0, 0] - 1) < 0.001
    assert abs(kin.K[0, 0] - rgb_only["K_kinect"][0, 0]) < 3 * u["kinect"]["std"]["fx"]
    assert abs(kin.K[0, 0] / ref["K_kinect"][0, 0] - 1) < 0.003
    # the external camera's pose in the Kinect's frame: within 0.1 deg and 1 mm of the published one
    # and within 3 of our own reported sigmas of it
    ang = _angle_deg(ext.R_cam_rig @ ref["R_ext_kinect"].T)
    dt_mm = 1000 * np.linalg.norm(ext.t_cam_rig - ref["t_ext_kinect"])
    assert ang <= 0.1 and dt_mm <= 1.0, (ang, dt_mm)
    ue = u["external"]
    assert ang < 3 * ue["rotation_sigma_deg"] and dt_mm < 3 * ue["translation_sigma_mm"]
    # the symmetric board calibrated as one board (no view set aside as flipped)
    assert not any("flipped" in w["reason"] or "left out" in w["reason"] for w in report["weak_views"])
    for cam in ("kinect", "external"):
        assert u[cam]["std"]["fx"] > 0
        assert u[cam]["lens_model"]["reason"]


def _opencv_repository_pipeline(session) -> dict:
    """The set's own repository's pipeline (its stereo_calibrate.py), plain OpenCV on the same
    pairs: findChessboardCorners, cornerSubPix (5 px thermal, 11 px ZED), calibrateCamera per
    camera, stereoCalibrate with the intrinsics fixed. Returns its RMS figures and baseline (m)."""
    obj = np.zeros((24, 3), np.float32)
    obj[:, :2] = np.indices((4, 6)).T.reshape(-1, 2) * 0.055
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 0.001)
    pts = {"thermal": [], "rgb": []}
    for pose in sorted(p for p in session.iterdir() if p.is_dir()):
        found = {}
        for cam, ext, win in (("thermal", "png", 5), ("rgb", "jpg", 11)):
            g = cv2.cvtColor(cv2.imread(str(pose / f"{cam}.{ext}")), cv2.COLOR_BGR2GRAY)
            ok, c = cv2.findChessboardCorners(g, (4, 6), None)
            if ok:
                found[cam] = cv2.cornerSubPix(g, c, (win, win), (-1, -1), crit)
        if len(found) == 2:
            for cam in pts:
                pts[cam].append(found[cam])
    objs = [obj] * len(pts["rgb"])
    rt = cv2.calibrateCamera(objs, pts["thermal"], (120, 160), None, None)
    rz = cv2.calibrateCamera(objs, pts["rgb"], (1280, 720), None, None)
    st = cv2.stereoCalibrate(objs, pts["thermal"], pts["rgb"], rt[1], rt[2], rz[1], rz[2], (1280, 720),
                             criteria=crit, flags=cv2.CALIB_FIX_INTRINSIC)
    R, T = st[5], st[6].ravel()
    cams = {"thermal": (rt[1], rt[2], pts["thermal"]), "rgb": (rz[1], rz[2], pts["rgb"])}
    rel = {("thermal", "rgb"): (R, T), ("rgb", "thermal"): (R.T, -R.T @ T)}
    epi = {}
    for (o, t), (R_to, t_to) in rel.items():  # mean distance to the epipolar line, target's undistorted px
        E = np.array([[0, -t_to[2], t_to[1]], [t_to[2], 0, -t_to[0]], [-t_to[1], t_to[0], 0]]) @ R_to
        Ko, Do, uo = cams[o]
        Kt, Dt, ut = cams[t]
        d = []
        for a, b in zip(uo, ut):
            xo = np.c_[cv2.undistortPoints(a, Ko, Do).reshape(-1, 2), np.ones(len(a))]
            xt = np.c_[cv2.undistortPoints(b, Kt, Dt).reshape(-1, 2), np.ones(len(b))]
            lines = (xo @ E.T) @ np.linalg.inv(Kt)
            pt = xt @ Kt.T
            d.append(np.abs(np.sum(lines * pt, axis=1)) / np.linalg.norm(lines[:, :2], axis=1))
        epi[(o, t)] = float(np.mean(np.concatenate(d)))
    return {"rgb_rms": rz[0], "stereo_rms": st[0], "baseline_m": float(np.linalg.norm(T)), "pairs": len(objs),
            "epipolar_px": epi}


def test_lepton_zed_calibrates_to_opencvs_figures_and_reports_its_uncertainty(shared_data, tmp_path, capsys):
    """The 4 x 6 board is symmetric and the thermal images are turned by 90 degrees: the views'
    corner orders are resolved against the rig. With the default --max-rms the ZED's corners must
    fit as well as plain OpenCV's (a glinting foil square pulled OpenCV's SB detector's corner up
    to 60 px off on 5 of 68 views: 2.14 px before), every thermal view must be found, and the
    relative pose must agree with OpenCV's stereoCalibrate on the same pairs (baseline: the set's
    README says ~110 mm, but the repository's own pipeline gives 73 mm; so does ours, and so does
    stereoCalibrate on our ordered corners, 73.4 mm; 69 mm with the one ZED view OpenCV finds
    and we do not). The pairs are hand-held and only
    approximately simultaneous, so the thermal camera's residuals in the joint fit are ~3x its
    own. The small board near the image centre leaves the ZED's focal length known to 0.9 % only,
    traded against the boards' distance: the rig is judged where it works (mrcal's figure over
    0.8-1.25x the boards' distance, docs/calibration.md) and calibrates with the default limits."""
    s = lepton_session(shared_data, tmp_path / "session")
    out = tmp_path / "out"
    out.mkdir()
    args = ["calibrate", str(s), "--out", str(out / "rig.json"), "--report", str(out / "report.json"), "--quiet"]
    code = main(args)
    err = capsys.readouterr().err
    assert code == 0, err
    assert "RMS error" not in err and "disagree" not in err and "Traceback" not in err, err
    assert "accepted_uncertain" not in Rig.load(out / "rig.json").extra["calibration"]
    rig = Rig.load(out / "rig.json")
    report = json.loads((out / "report.json").read_text())
    ref = _opencv_repository_pipeline(s)
    assert report["detection"]["cameras"]["thermal"]["found"] >= 66
    u = report["uncertainty"]["thermal"]
    assert u["rotation_sigma_deg"] > 0 and u["translation_sigma_mm"] > 0
    # the ZED fits its corners no worse than OpenCV's plain pipeline its own
    assert rig.extra["calibration"]["cameras"]["rgb"]["rms_px"] <= ref["rgb_rms"]
    # the relative pose: epipolar errors (both directions, each in the target's pixels) no worse than
    # those of OpenCV's stereoCalibrate pose on its own corners (its reprojection RMS, ~1.5 px, is
    # another measure: thermal -> ZED lines are in ZED pixels, 5.7 to a thermal pixel); the
    # baseline within 3 of our reported sigmas of OpenCV's (which moves by 4 mm with one view more)
    for (o, t), px in ref["epipolar_px"].items():
        assert report["extrinsic"][o][t]["px"] <= px, (o, t, report["extrinsic"][o][t], ref)
    dt_mm = 1000 * abs(np.linalg.norm(rig.camera("thermal").center_rig) - ref["baseline_m"])
    assert dt_mm < 3 * u["translation_sigma_mm"], (dt_mm, u["translation_sigma_mm"], ref)
    th = rig.camera("thermal")
    assert 130 < th.K[0, 0] < 200  # OpenCV: ~158 px on these views
