"""Boards, sessions and corner detection: order rule, polarity, ChArUco, board-size suggestion.

Images are rendered with the synthetic session's renderer through a known camera, so the true
corner positions are the projections of the board's object points.
"""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from plantreg_gui.core.calibration import (Board, DetectOptions, Session, detect_image, detect_session,
                                           suggest_board_size)
from plantreg_gui.core.calibration.synthetic import _CamRays, _rot, render_board
from plantreg_gui.core.camera.camera import Camera
from plantreg_gui.core.errors import InputError

CAM = Camera("c", "visible", 640, 480, [[600, 0, 322], [0, 600, 238], [0, 0, 1]], [0.05, -0.02, 0, 0, 0])
RAYS = _CamRays(CAM)


def _render(board: Board, R: np.ndarray, t: np.ndarray, negative: bool = False, contrast: float = 1.0):
    """uint8 image of ``board`` at pose (R_cam_board, t) and the true corners (N, 2)."""
    refl, cover, _z = render_board(RAYS, board, R, t)
    img = 0.5 + contrast * ((0.05 + 0.85 * refl) - 0.5)
    img = cover * img + (1 - cover) * 0.35
    if negative:
        img = 1.0 - img
    img = cv2.GaussianBlur(img, (0, 0), 0.7)
    img = np.clip(img * 255 + np.random.default_rng(0).normal(0, 1.0, img.shape), 0, 255).astype(np.uint8)
    uv, _ = CAM.project(board.object_points() @ R.T + t)
    return img, uv


def _pose(board: Board, roll_deg: float = 0.0, tilt_deg: float = 20.0, z: float = 0.6):
    s = board.square_size
    c = np.array([(board.columns - 1) * s / 2, (board.rows - 1) * s / 2, 0])
    R = _rot("z", roll_deg) @ _rot("x", tilt_deg) @ _rot("y", -10)
    return R, np.array([0.01, -0.01, z]) - R @ c


# ---------------------------------------------------------------------- board
def test_board_geometry_and_serialisation():
    b = Board("chessboard", 9, 6, 0.025)
    obj = b.object_points()
    assert obj.shape == (54, 3)
    assert np.allclose(obj[1], [0.025, 0, 0]) and np.allclose(obj[9], [0, 0.025, 0])  # row by row
    assert not b.is_symmetric and Board("chessboard", 8, 6, 0.02).is_symmetric
    assert Board.from_dict(b.to_dict()) == b
    img = b.render(px_per_square=20)
    assert img.shape == (7 * 20 + 20, 10 * 20 + 20) and img.dtype == np.uint8
    assert img[10 + 5, 10 + 5] == 0  # the outer top-left square is black
    with pytest.raises(ValueError, match="inner corners"):
        Board("chessboard", 1, 6, 0.02)
    with pytest.raises(ValueError, match="marker_size"):
        Board("charuco", 5, 4, 0.04)


# ---------------------------------------------------------------------- order and polarity
@pytest.mark.parametrize("roll", [0.0, 90.0, 180.0, -150.0])
def test_order_is_unique_for_both_polarities(roll):
    """The same physical corner comes first whatever the in-plane rotation and the polarity
    (the thermal case: a negative image, detected with invert=True)."""
    b = Board("chessboard", 9, 6, 0.03)
    R, t = _pose(b, roll)
    img, truth = _render(b, R, t)
    d = detect_image(img, b, DetectOptions(invert=False))
    assert d.found and np.abs(d.corners - truth).max() < 0.3
    neg, _ = _render(b, R, t, negative=True, contrast=0.3)
    d = detect_image(neg, b, DetectOptions(invert=True))
    assert d.found and np.abs(d.corners - truth).max() < 0.4
    # the modality decides when invert is None: thermal -> negative
    d = detect_image(neg, b, DetectOptions(), modality="thermal")
    assert d.inverted and np.abs(d.corners - truth).max() < 0.4


def test_wrong_polarity_flips_the_order():
    """Why the polarity matters: a negative board read as a positive one comes back rotated by
    180 degrees (the first corner is the truth's last), which calibrate() then flags."""
    b = Board("chessboard", 9, 6, 0.03)
    R, t = _pose(b, 10.0)
    neg, truth = _render(b, R, t, negative=True)
    d = detect_image(neg, b, DetectOptions(invert=False))
    assert d.found
    assert np.abs(d.corners - truth[::-1]).max() < 0.4


def test_low_contrast_and_multiband_and_float():
    b = Board("chessboard", 9, 6, 0.03)
    R, t = _pose(b, 5.0, 30.0)
    img, truth = _render(b, R, t, contrast=0.08)
    d = detect_image(img, b)
    assert d.found and np.abs(d.corners - truth).max() < 0.6
    # float "temperatures" and a multi-band cube go through the same detector
    temps = 25.0 + 3.0 * img.astype(np.float32) / 255.0
    assert detect_image(temps, b).found
    cube = np.repeat(img[..., None].astype(np.float32) / 255.0, 6, axis=2)
    assert detect_image(cube, b).found


def test_failure_has_reason_and_size_suggestion():
    b = Board("chessboard", 9, 6, 0.03)
    R, t = _pose(b)
    img, _ = _render(b, R, t)
    wrong = Board("chessboard", 10, 7, 0.03)  # squares counted instead of inner corners
    d = detect_image(img, wrong)
    assert d.status == "failed" and "10x7" in d.reason
    assert suggest_board_size([img], wrong) == (9, 6)
    blank = detect_image(np.zeros((100, 100), np.uint8), b)
    assert blank.status == "failed" and "blank" in blank.reason


def test_charuco_detection_with_ids():
    b = Board("charuco", 6, 4, 0.04, 0.03, "DICT_4X4_50")
    p = 60
    pic = b.render(px_per_square=p, margin_squares=1.0)
    img = np.full((pic.shape[0] + 100, pic.shape[1] + 100), 128, np.uint8)
    img[50 : 50 + pic.shape[0], 50 : 50 + pic.shape[1]] = pic
    d = detect_image(img, b)
    assert d.found and len(d.ids) == b.n_corners
    assert np.all(np.diff(d.ids) > 0)
    # inner corner (i, j) lies at 50 + (1 + margin + i) * p - 0.5 (pixel centres at integers)
    obj = d.object_points(b)
    expect = 50 + (2 + obj[:, :2] / b.square_size) * p - 0.5
    assert np.abs(d.corners - expect).max() < 0.5


# ---------------------------------------------------------------------- sessions
def test_session_create_add_review_reopen_remove(tmp_path):
    b = Board("chessboard", 9, 6, 0.03)
    s = Session.create(tmp_path / "sess", b, {"cam": "visible", "th": "thermal"})
    src = tmp_path / "capture"
    src.mkdir()
    R, t = _pose(b)
    img, _ = _render(b, R, t)
    cv2.imwrite(str(src / "cam.png"), img)
    pose = s.add_pose_from_folder(src)
    assert pose.name == "capture" and set(pose.images) == {"cam"}
    pose2 = s.add_pose_from_folder(src)  # the same folder again gets a fresh name
    assert pose2.name != pose.name and len(s.poses) == 2
    s.set_excluded({(pose.name, "cam")})
    s.set_detect_options(pose2.name, "cam", DetectOptions(invert=True, enhance=True))
    s.save()
    r = Session.load(tmp_path / "sess")
    assert r.excluded() == {(pose.name, "cam")}
    assert r.detect_options()[(pose2.name, "cam")] == DetectOptions(invert=True, enhance=True)
    assert r.default_inverted("th") and not r.default_inverted("cam")
    dets = list(detect_session(r))
    assert [(d.pose, d.camera, d.status) for d in dets] == [
        (pose.name, "cam", "found"), (pose.name, "th", "missing"), (pose2.name, "cam", "found"), (pose2.name, "th", "missing")]
    r.remove_pose(pose.name)
    assert [p.name for p in Session.load(tmp_path / "sess").poses] == [pose2.name]
    assert Session.load(tmp_path / "sess").excluded() == set()
    with pytest.raises(InputError, match="no image named after a camera"):
        r.add_pose_from_folder(tmp_path)


def test_session_errors_name_the_file(tmp_path):
    with pytest.raises(InputError, match="no session.json"):
        Session.load(tmp_path)
    (tmp_path / "session.json").write_text("{ not json")
    with pytest.raises(InputError, match="session.json.*not valid JSON"):
        Session.load(tmp_path)
    (tmp_path / "session.json").write_text(json.dumps({"board": {"columns": 9, "rows": 6, "square_size": 0.02},
                                                        "cameras": {"a": {}}, "depth": {"camera": "x"}}))
    with pytest.raises(InputError, match="depth camera 'x'"):
        Session.load(tmp_path)
    # a hand-edited review block of the wrong shape: a clear error, not a traceback (options) or
    # a string silently iterated character by character (excluded)
    board = {"type": "chessboard", "columns": 9, "rows": 6, "square_size": 0.02}
    for bad_board in ({"columns": 8.5}, {"rows": True}):
        (tmp_path / "session.json").write_text(json.dumps({"board": {**board, **bad_board}, "cameras": {"a": {}}}))
        with pytest.raises(InputError, match="whole number of inner corners"):
            Session.load(tmp_path)
    for review, words in (({"options": ["pose_01:a"]}, "review.options"),
                          ({"excluded": "pose_01:a"}, "review.excluded"), ([1], "review")):
        (tmp_path / "session.json").write_text(json.dumps({"board": board, "cameras": {"a": {}}, "review": review}))
        with pytest.raises(InputError, match=words) as e:
            Session.load(tmp_path)
        assert "session.json" in str(e.value)


def test_charuco_session_end_to_end(tmp_path):
    """A ChArUco session of a wide infrared (depth) camera and a narrow inverted thermal camera:
    partial views count; the calibration recovers the truth."""
    from plantreg_gui.core.calibration import calibrate, error_tables, read_truth, write_calibration_session
    from plantreg_gui.core.calibration.synthetic import example_rig
    from plantreg_gui.core.camera.rig import Rig

    full = example_rig()
    rig = Rig([full.camera("ir"), full.camera("thermal")], "ir")
    b = Board("charuco", 11, 7, 0.03, 0.022, "DICT_4X4_50")
    folder = write_calibration_session(rig, tmp_path / "charuco", seed=1, n_poses=10, board=b)
    s = Session.load(folder)
    truth = read_truth(folder)
    dets = {d.key: d for d in detect_session(s)}
    partial = [d for d in dets.values() if d.found and len(d.ids) < b.n_corners]
    assert partial, "expected some partial ChArUco views"
    for (pose, cam), d in dets.items():
        if d.found:
            R, t = truth["board_poses"][pose]
            uv, _ = truth["rig"].camera(cam).project(b.object_points()[d.ids] @ R.T + t)
            assert np.median(np.linalg.norm(d.corners - uv, axis=1)) < 0.7, (pose, cam)
    cal = calibrate(s, dets)
    for c in cal.rig.cameras:
        t = truth["rig"].camera(c.name)
        assert abs(c.K[0, 0] / t.K[0, 0] - 1) < 0.01
        assert np.linalg.norm(c.center_rig - t.center_rig) < 0.005
    rep = error_tables(s, cal, dets)
    assert rep.extrinsic["ir"]["thermal"]["px"] < 1.0 and rep.depth["ir"]["thermal"]["px"] < 3.0


def test_depth_table_is_near_zero_without_tof_bias(tmp_path):
    """Ground truth for the depth table: with an unbiased, noise-free depth camera (only mm
    quantisation) carrying corners through the depth mesh lands on the detected corners (errors
    of the order of the corner noise); a 6 mm ToF bias shows up as larger errors and as the
    recovered bias."""
    from plantreg_gui.core.calibration import calibrate, error_tables, write_calibration_session
    from plantreg_gui.core.calibration.synthetic import example_rig
    from plantreg_gui.core.camera.rig import Rig

    full = example_rig()
    rig = Rig([full.camera("ir"), full.camera("thermal"), full.camera("hyperspectral")], "ir")
    out = {}
    for bias in (0.0, 6.0):
        folder = write_calibration_session(rig, tmp_path / f"b{bias:g}", seed=2, n_poses=6,
                                           tof_bias_mm=(bias, 0.0), tof_noise_mm=0.0)
        s = Session.load(folder)
        dets = {d.key: d for d in detect_session(s)}
        cal = calibrate(s, dets)
        out[bias] = error_tables(s, cal, dets)
    for o in ("ir", "thermal", "hyperspectral"):
        for t in ("ir", "thermal", "hyperspectral"):
            if o != t:
                # the rendered thermal board is lamp-heated with a faint checker (its corners are
                # noisier, 0.25-0.45 px median per view): pairs with it get more room
                limit = 0.5 if "thermal" in (o, t) else 0.25
                assert out[0.0].depth[o][t]["px"] < limit, (o, t, out[0.0].depth[o][t])
                assert out[6.0].depth[o][t]["px"] > out[0.0].depth[o][t]["px"]
    # within 1 mm: the board poses are estimated jointly with the lamp-heated thermal camera
    assert all(abs(b) < 1.0 for b in out[0.0].depth_bias_mm.values()), out[0.0].depth_bias_mm
    assert all(abs(b - 6.0) < 1.0 for b in out[6.0].depth_bias_mm.values()), out[6.0].depth_bias_mm


def test_grid_irregularity_tells_a_misplaced_corner_from_perspective_and_distortion():
    """A steep view through a strongly distorting lens keeps its grid lines smooth; one corner
    pulled a square away (a glint on a foil square) does not (detect.MAX_IRREGULARITY)."""
    from plantreg_gui.core.calibration.board import Board
    from plantreg_gui.core.calibration.detect import MAX_IRREGULARITY, grid_irregularity

    board = Board("chessboard", 4, 6, 0.055)
    obj = board.object_points().astype(np.float64)
    K = np.array([[160.0, 0, 60], [0, 160.0, 80], [0, 0, 1]])
    worst_real = 0.0
    for tilt in (0, 30, 50):
        for k1 in (0.0, -0.4):
            rv = np.array([np.radians(tilt), np.radians(tilt / 2), 0.3])
            uv = cv2.projectPoints(obj, rv, np.array([-0.1, -0.15, 0.6]), K, np.array([k1, 0.9 * abs(k1), 0, 0]))[0]
            uv = uv.reshape(-1, 2)
            worst_real = max(worst_real, grid_irregularity(uv, board))
            bad = uv.copy()
            g = bad.reshape(6, 4, 2)
            g[5, 0] -= g[5, 1] - g[5, 0]  # the corner one square further out
            assert grid_irregularity(bad, board) > MAX_IRREGULARITY
    assert worst_real < MAX_IRREGULARITY, worst_real
