"""The solver against known truth: uncertainty that means what it says, symmetric boards, lens
model choice, refusal of sessions the data do not determine, known intrinsics.

Sessions are simulated at the corner level (tests/calsim.py: known rig and board poses, Gaussian
detection noise). The seeds asserted here were not the ones the limits and rules were developed
on (those were 0-31)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from calsim import board_poses, simulate, true_among_boards_errors, true_projection_errors, webcam_rig
from plantreg_gui.core.calibration import Board, calibrate
from plantreg_gui.core.calibration.calibrate import KnownIntrinsics
from plantreg_gui.core.calibration.uncertainty import LIMIT_BAND


def _angle_deg(R: np.ndarray) -> float:
    return float(np.degrees(np.arccos(np.clip((np.trace(R) - 1) / 2, -1, 1))))


def _session(seed: int, coverage: str, n_cams: int = 3, board=None, n_poses=None, noise=None, **kw):
    rng = np.random.default_rng(seed)
    rig = webcam_rig(n_cams, rng)
    board = board or Board("chessboard", 9, 6, 0.03)
    poses = board_poses(rig, board, n_poses or 12 + seed % 3 * 4, rng, coverage)
    s, dets, flipped = simulate(rig, board, poses, rng, noise_px=noise or 0.1 + 0.1 * (seed % 3), **kw)
    return rig, s, dets, flipped


def test_projection_uncertainty_covers_the_true_error():
    """On 22 sessions (boards all over the image or in its centre only; 3 cameras each; 12-20
    poses; noise 0.1-0.3 px) the true projection error lies within the reported 2 sigma in 90-98 %
    of the image points, for the lens model alone, for the camera in the rig, and for mrcal's
    figure (the point fixed among the board poses) at each distance of the working band the
    limits judge (0.8x, 1x, 1.25x the working distance). (Fronto-parallel sessions: see the
    refusal tests.)"""
    inside_i, inside_r = [], []
    inside_b: dict[float, list] = {f: [] for f in LIMIT_BAND}
    for k, seed in enumerate(range(100, 122)):
        rng = np.random.default_rng(seed)
        rig = webcam_rig(3, rng)
        board = Board("chessboard", 9, 6, 0.03)
        poses = board_poses(rig, board, 12 + seed % 3 * 4, rng, ("spread", "centre")[k % 2])
        s, dets, _ = simulate(rig, board, poses, rng, noise_px=0.1 + 0.1 * (seed % 3))
        cal = calibrate(s, dets)
        for cam in s.cameras:
            e_i, s_i, e_r, s_r = true_projection_errors(cal, rig, cam)
            inside_i.append(np.mean(e_i <= 2 * s_i))
            inside_r.append(np.mean(e_r <= 2 * s_r))
            for f in LIMIT_BAND:
                e_b, s_b = true_among_boards_errors(cal, rig, cam, poses, f)
                inside_b[f].append(np.mean(e_b <= 2 * s_b))
    assert 0.90 <= np.mean(inside_i) <= 0.98, np.round(inside_i, 2)
    assert 0.90 <= np.mean(inside_r) <= 0.98, np.round(inside_r, 2)
    for f, inside in inside_b.items():
        assert 0.90 <= np.mean(inside) <= 0.98, (f, np.round(inside, 2))


@pytest.mark.parametrize("seed", [200, 201, 202])
def test_symmetric_board_with_random_corner_orders(seed):
    """An 8 x 6 board (looks the same turned by 180 degrees): the detector's order is reversed in
    a random half of the views; every pose comes out with one consistent order across cameras and
    the rig matches the truth within 3 sigma."""
    rig, s, dets, flipped = _session(seed, "spread", board=Board("chessboard", 8, 6, 0.03), n_poses=15,
                                     noise=0.2, flip_symmetric=True)
    assert len(flipped) > 5
    cal = calibrate(s, dets)
    for pose in {p for p, _c in dets}:
        # reversed by us xor by the "detector": the same for every camera of the pose
        assert len({((p, c) in cal.flipped) ^ ((p, c) in flipped) for p, c in dets if p == pose}) == 1, pose
    assert not any("disagrees" in w[3] for w in cal.weak_views)
    for c in rig.cameras[1:]:
        e, u = cal.rig.camera(c.name), cal.uncertainty[c.name]
        assert _angle_deg(e.R_cam_rig @ c.R_cam_rig.T) < 3 * u.rotation_deg
        assert 1000 * np.linalg.norm(e.t_cam_rig - c.t_cam_rig) < 3 * u.translation_mm
    assert not cal.uncertainty_problems()


@pytest.mark.parametrize("seed", [302, 305, 308])
def test_fronto_parallel_session_is_refused_naming_camera_and_parameter(seed):
    """Boards all facing the reference camera (Zhang's degenerate case: parallel board planes):
    the focal lengths are not determined; the calibration says so for every camera, naming the
    camera and the parameter."""
    _rig, s, dets, _ = _session(seed, "fronto")
    cal = calibrate(s, dets)
    problems = cal.uncertainty_problems()
    import re

    for cam in s.cameras:
        mine = [p for p in problems if p.startswith(f"camera '{cam}': ")]
        assert mine, (cam, problems)
        assert re.search(r"least determined: (fx|fy) \+- ", mine[0]), mine[0]
        assert "add board views" in mine[0]


@pytest.mark.parametrize("seed", [303, 306])
def test_boards_tilted_in_a_few_views_determine_the_focal_length(seed):
    """The refusal of parallel boards is not a refusal of fronto-parallel views: the same fronto
    session with four tilted views added calibrates without a problem, and its focal lengths lie
    within 3 of their reported sigmas of the truth."""
    rng = np.random.default_rng(seed)
    rig = webcam_rig(3, rng)
    board = Board("chessboard", 9, 6, 0.03)
    poses = board_poses(rig, board, 14, rng, "fronto") + board_poses(rig, board, 4, rng, "spread")
    s, dets, _ = simulate(rig, board, poses, rng, noise_px=0.2)
    cal = calibrate(s, dets)
    assert not [p for p in cal.uncertainty_problems() if "turned within" in p], cal.uncertainty_problems()
    for c in rig.cameras:
        assert abs(cal.rig.camera(c.name).K[0, 0] - c.K[0, 0]) < 3 * cal.uncertainty[c.name].std["fx"]


@pytest.mark.parametrize("seed", [310, 311, 312, 313])
def test_few_partial_charuco_views_are_refused_or_right(seed):
    """The kept-back 4-webcam ChArUco failure (exit 0 with poses 4-18 degrees wrong): few, partial
    views of a small 4 x 5 board near the image centre. Every camera's pose is either refused by
    name or within 3 of its reported sigmas of the truth, with its principal point near the truth."""
    board = Board("charuco", 4, 5, 0.05, 0.037, "DICT_4X4_50")
    rng = np.random.default_rng(seed)
    rig = webcam_rig(4, rng)
    poses = board_poses(rig, board, 8, rng, "centre", depth=(0.7, 1.2))
    s, dets, _ = simulate(rig, board, poses, rng, noise_px=0.3, partial=0.6)
    cal = calibrate(s, dets)
    for c in rig.cameras[1:]:
        e, u = cal.rig.camera(c.name), cal.uncertainty[c.name]
        if any(p.startswith(f"camera '{c.name}': its pose relative to the reference") for p in cal.uncertainty_problems()):
            continue  # its pose refused by name
        assert _angle_deg(e.R_cam_rig @ c.R_cam_rig.T) < 3 * u.rotation_deg
        assert 1000 * np.linalg.norm(e.t_cam_rig - c.t_cam_rig) < 3 * u.translation_mm
        assert np.abs(e.K[:2, 2] - c.K[:2, 2]).max() < 3 * max(u.std["cx"], u.std["cy"])


def test_lens_model_choice_is_recorded_with_its_cross_validation():
    rig, s, dets, _ = _session(400, "spread", n_poses=16, noise=0.15)
    cal = calibrate(s, dets)
    for cam in s.cameras:
        lm = cal.intrinsics[cam].lens_model_dict()
        assert lm["model"] in ("k1k2", "k1k2-tan", "k1k2k3-tan", "rational")
        assert lm["cv_rms_px"]["k1k2"] is not None and lm["reason"]
        # the truth has k1, k2 only: the choice never adds the rational terms
        assert lm["model"] != "rational"
    prov = cal.provenance()
    assert prov["cameras"]["cam1"]["lens_model"]["model"] == cal.intrinsics["cam1"].model.model.name
    assert prov["cameras"]["cam1"]["uncertainty"]["std"]["fx"] > 0


def test_known_intrinsics_fixed_and_as_priors():
    rig, s, dets, _ = _session(500, "spread", n_poses=15, noise=0.2)
    true1 = rig.camera("cam1")
    fixed = KnownIntrinsics(true1.K.copy(), np.asarray(true1.dist, float).copy(), {}, "test")
    cal = calibrate(s, dets, known={"cam1": fixed})
    c1 = cal.rig.camera("cam1")
    assert np.allclose(c1.K, true1.K) and np.allclose(c1.dist, true1.dist)
    assert cal.uncertainty["cam1"].std["fx"] == 0.0  # held: no uncertainty of its own
    assert _angle_deg(c1.R_cam_rig @ true1.R_cam_rig.T) < 3 * cal.uncertainty["cam1"].rotation_deg
    assert cal.intrinsics["cam1"].lens_model_dict()["model"] == "given"
    # priors: a wrong fx given with a large standard error is corrected by the data
    K = true1.K.copy()
    K[0, 0] *= 1.02
    prior = KnownIntrinsics(K, np.asarray(true1.dist, float).copy(), {"fx": 50.0, "fy": 50.0, "cx": 20.0, "cy": 20.0},
                            "test")
    cal = calibrate(s, dets, known={"cam1": prior})
    assert abs(cal.rig.camera("cam1").K[0, 0] - true1.K[0, 0]) < 0.3 * abs(K[0, 0] - true1.K[0, 0])
    assert 0 < cal.uncertainty["cam1"].std["fx"] < 50.0


def test_views_are_asked_for_exactly_where_a_limit_is_exceeded():
    """"Add views here" (the report's add_views_here, the heat map's outline) only for a camera
    whose projection uncertainty exceeds a limit; a camera within the limits names only its least
    certain regions. Sessions with boards all over the image and with few boards in the centre."""
    seen = set()
    for seed, coverage, n in ((220, "spread", 15), (221, "centre", 5), (222, "centre", 4)):
        _rig, s, dets, _ = _session(seed, coverage, n_poses=n)
        cal = calibrate(s, dets)
        problems = cal.uncertainty_problems()
        for cam, u in cal.uncertainty.items():
            exceeded = any(p.startswith(f"camera '{cam}': projection uncertainty") for p in problems)
            d = u.to_dict()
            assert u.needs_views == exceeded, (seed, cam, problems)
            assert bool(d["add_views_here"]) == exceeded and d["least_certain_regions"]
            seen.add(exceeded)
    assert seen == {True, False}


def _thermal_pair(seed: int):
    """A 1280 x 720 webcam and a 160 x 120 thermal-sized camera (f 165 px) 0.1 m beside it."""
    from calsim import look_at
    from plantreg_gui.core.camera.camera import Camera
    from plantreg_gui.core.camera.rig import Rig

    rng = np.random.default_rng(seed)
    web = webcam_rig(1, rng).cameras[0]
    R, t = look_at([0.1, 0.0, 0.0], [0.0, 0.0, 0.8])
    th = Camera("thermal", "thermal", 160, 120, [[165, 0, 79.5], [0, 165, 59.5], [0, 0, 1]],
                [-0.1, 0.05, 0, 0, 0], R, t)
    return Rig([web, th], None, 0.001), rng


@pytest.mark.parametrize("seed", [230, 231])
def test_a_view_is_weak_by_its_own_pose_uncertainty_not_by_a_fixed_angle(seed):
    """The board pose a 160 px camera gets from one view is uncertain by a degree or more, so
    disagreeing with the rig by 1-3 degrees is not a fault (a fixed 1 degree flagged most views
    of the real Lepton set, 46 of 69). A view whose board really moved between the two exposures
    (turned by 10 degrees when the webcam took its image) is still named."""
    rig, rng = _thermal_pair(seed)
    board = Board("chessboard", 9, 6, 0.03)
    poses = board_poses(rig, board, 16, rng, "spread", depth=(0.6, 1.0))
    s, dets, _ = simulate(rig, board, poses, rng, noise_px=0.3)
    k = min(int(p.split("_")[1]) - 1 for p, c in dets if c == "thermal" and (p, "cam0") in dets)
    name = f"pose_{k + 1:03d}"
    Rk, tk = poses[k]
    c = Rk @ np.array([0.12, 0.075, 0.0]) + tk
    turn = cv2.Rodrigues(np.radians([10.0, 0.0, 0.0]))[0]
    moved = [(turn @ Rk, turn @ (tk - c) + c) if j == k else p for j, p in enumerate(poses)]
    _s2, dets2, _ = simulate(rig, board, moved, np.random.default_rng(seed + 1), noise_px=0.3)
    dets[(name, "cam0")] = dets2[(name, "cam0")]
    cal = calibrate(s, dets)
    weak = {(c, p): r for c, cc in cal.intrinsics.items() for p, _e, r in cc.weak_views if "disagrees" in r}
    assert ("cam0", name) in weak or ("thermal", name) in weak, weak
    assert not [v for v in weak if v[1] != name], weak
