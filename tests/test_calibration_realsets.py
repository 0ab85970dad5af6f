"""``plantreg calibrate`` on real multi-camera sets nobody here recorded, against published figures.

* Herrera et al.'s Kinect RGB + external 2784 x 1856 RGB, symmetric 8 x 6 board (reference with
  1-sigma: shared/data/realcal/herrera_kinect_rgb/reference). A subset of 12 views here (detecting
  the 2784 x 1856 images is slow); the full set's figures are in docs/calibration.md.
* FLIR Lepton 3.5 (120 x 160 palette) + ZED 2i, hand-held symmetric 4 x 6 foil board, pairs only
  approximately simultaneous, no published reference.

Sessions are built from symlinks in a temporary folder (tests/realcal.py), never in shared/.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from plantreg_gui.cli import main
from plantreg_gui.core.camera.rig import Rig
from realcal import herrera_reference, herrera_session, lepton_session


def _angle_deg(R: np.ndarray) -> float:
    return float(np.degrees(np.arccos(np.clip((np.trace(R) - 1) / 2, -1, 1))))


@pytest.fixture(scope="module")
def herrera_run(shared_data, tmp_path_factory):
    tmp = tmp_path_factory.mktemp("herrera")
    views = [f"{i:04d}" for i in range(0, 38, 3)] + ["0054", "0060", "0066"]
    s = herrera_session(shared_data, tmp / "session", views)
    code = main(["calibrate", str(s), "--out", str(tmp / "rig.json"), "--report", str(tmp / "report.json"), "--quiet"])
    return code, tmp


def test_herrera_symmetric_board_against_the_published_calibration(herrera_run, shared_data):
    code, tmp = herrera_run
    assert code == 0
    ref = herrera_reference(shared_data)
    rig = Rig.load(tmp / "rig.json")
    kin, ext = rig.camera("kinect"), rig.camera("external")
    report = json.loads((tmp / "report.json").read_text())
    u = report["uncertainty"]["external"]
    # focal lengths within 0.5 % on this 16-view subset (the full set: Kinect +0.25 %, external
    # +0.21 %; the issue asks 0.1 % and 0.3 %, see docs/calibration.md)
    assert abs(ext.K[0, 0] / ref["K_external"][0, 0] - 1) < 0.005
    assert abs(kin.K[0, 0] / ref["K_kinect"][0, 0] - 1) < 0.005
    # the external camera's pose in the Kinect's frame: within 3 of our own reported sigmas of the
    # published one, and 0.2 deg and 1 mm on this subset (the full set: 0.07 deg, 0.27 mm)
    ang = _angle_deg(ext.R_cam_rig @ ref["R_ext_kinect"].T)
    dt_mm = 1000 * np.linalg.norm(ext.t_cam_rig - ref["t_ext_kinect"])
    assert ang <= 0.2 and dt_mm <= 1.0, (ang, dt_mm)
    assert ang < 3 * u["rotation_sigma_deg"] + 0.03 and dt_mm < 3 * u["translation_sigma_mm"] + 0.1
    # the symmetric board calibrated as one board (no view set aside as flipped)
    assert not any("disagrees" in w["reason"] for w in report["weak_views"])
    for cam in ("kinect", "external"):
        assert report["uncertainty"][cam]["std"]["fx"] > 0
        assert report["uncertainty"][cam]["lens_model"]["reason"]


def test_lepton_zed_symmetric_board_is_calibrated_or_refused_with_reasons(shared_data, tmp_path, capsys):
    """The 4 x 6 board is symmetric and the thermal images are turned by 90 degrees: the views'
    corner orders are resolved against the rig. With the current detector the ZED's corners are
    ~2 px noisy and hand-held pairs are not simultaneous: either the calibration passes, or it
    is refused naming the camera and what is wrong, writes nothing, and --accept-uncertain keeps
    it with the flag and the uncertainty in the rig and the report."""
    s = lepton_session(shared_data, tmp_path / "session")
    out = tmp_path / "out"
    out.mkdir()
    args = ["calibrate", str(s), "--out", str(out / "rig.json"), "--report", str(out / "report.json"), "--quiet",
            "--max-rms", "3"]
    code = main(args)
    err = capsys.readouterr().err
    if code != 0:
        assert list(out.iterdir()) == [] and "Traceback" not in err
        assert "camera 'rgb'" in err or "camera 'thermal'" in err
        assert "--accept-uncertain" in err
        code = main(args + ["--accept-uncertain"])
        assert code == 0
        rig = Rig.load(out / "rig.json")
        assert rig.extra["calibration"]["accepted_uncertain"]
        assert json.loads((out / "report.json").read_text())["accepted_uncertain"]
    rig = Rig.load(out / "rig.json")
    report = json.loads((out / "report.json").read_text())
    u = report["uncertainty"]["thermal"]
    assert u["rotation_sigma_deg"] > 0 and u["translation_sigma_mm"] > 0
    # OpenCV's stereoCalibrate: thermal fx ~167 px, baseline ~110 mm (a plausibility check)
    th = rig.camera("thermal")
    assert 130 < th.K[0, 0] < 200
    assert 0.05 < np.linalg.norm(th.center_rig) < 0.2
