"""Calibration sessions simulated at the corner level (no rendering): the board corners of known
board poses projected through a known rig, plus Gaussian detection noise. Fast enough for many
seeds; the rendered sessions of ``core/calibration/synthetic.py`` test the detector on top.

``coverage``: "spread" (boards tilted up to ~50 degrees all over the image, the way a careful
technician records), "centre" (every board in the middle third of the reference image),
"fronto" (boards facing the camera, tilts below 3 degrees).
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from plantreg_gui.core.calibration import FOUND, Board, Detection, Session
from plantreg_gui.core.camera.camera import Camera
from plantreg_gui.core.camera.rig import Rig


def _rot(axis: str, deg: float) -> np.ndarray:
    return cv2.Rodrigues(np.deg2rad(deg) * np.eye(3)["xyz".index(axis)])[0]


def look_at(centre, target, roll_deg=0.0):
    """R_cam_rig, t_cam_rig of a camera at ``centre`` (rig frame) turned (yaw, then pitch) to look
    at ``target``, then rolled."""
    c = np.asarray(centre, float)
    d = np.asarray(target, float) - c
    yaw = np.degrees(np.arctan2(d[0], d[2]))
    pitch = -np.degrees(np.arctan2(d[1], np.hypot(d[0], d[2])))
    R = _rot("z", roll_deg) @ (_rot("y", yaw) @ _rot("x", pitch)).T
    return R, -R @ c


def webcam_rig(n: int = 4, rng: np.random.Generator | None = None) -> Rig:
    """``n`` 1280 x 720 webcams (f ~ 900 px, mild distortion) on an arc ~0.3 m apart, looking at
    a point 0.8 m ahead."""
    rng = rng or np.random.default_rng(0)
    cams = []
    for i in range(n):
        f = 900 + rng.uniform(-60, 60)
        K = [[f, 0, 639.5 + rng.uniform(-15, 15)], [0, f * 1.002, 359.5 + rng.uniform(-10, 10)], [0, 0, 1]]
        dist = [rng.uniform(-0.15, 0.05), rng.uniform(-0.05, 0.15), 0.0, 0.0, 0.0]
        if i == 0:
            R, t = np.eye(3), np.zeros(3)
        else:
            ang = np.radians(25 * i - 10 * (n - 1))
            R, t = look_at([0.4 * np.sin(ang), rng.uniform(-0.05, 0.05), 0.8 - 0.8 * np.cos(ang)], [0, 0, 0.8],
                           rng.uniform(-3, 3))
        cams.append(Camera(f"cam{i}", "visible", 1280, 720, K, dist, R, t))
    return Rig(cams, None, 0.001)


def board_poses(rig: Rig, board: Board, n: int, rng: np.random.Generator, coverage: str = "spread",
                depth=(0.5, 1.1)) -> list[tuple[np.ndarray, np.ndarray]]:
    """``n`` poses (R_rig_board, t_rig_board) in front of the reference camera (cameras[0])."""
    ref = rig.cameras[0]
    s = board.square_size
    centre = np.array([(board.columns - 1) * s / 2, (board.rows - 1) * s / 2, 0.0])
    out = []
    for _ in range(n):
        z = rng.uniform(*depth)
        if coverage == "fronto":
            tilt = rng.uniform(0, 3)
        else:
            tilt = rng.uniform(10, 50)
        phi = rng.uniform(0, 2 * np.pi)
        R = _rot("z", rng.uniform(-15, 15)) @ _rot("x", tilt * np.sin(phi)) @ _rot("y", tilt * np.cos(phi))
        frac = 0.1 if coverage == "centre" else 0.35
        px = np.array([[ref.width * (0.5 + rng.uniform(-frac, frac)), ref.height * (0.5 + rng.uniform(-frac, frac))]])
        o, d = ref.rays_rig(px)
        p = o + d[0] * (z - o[2]) / d[0, 2]
        out.append((R, p - R @ centre))
    return out


def simulate(rig: Rig, board: Board, poses, rng: np.random.Generator, noise_px: float = 0.15,
             partial: float = 0.0, flip_symmetric: bool = False, folder: str | Path = "/nonexistent"):
    """(Session, detections {(pose, cam): Detection}, flipped {(pose, cam)}): the corners of each
    pose projected into each camera that sees at least 80 % of them (ChArUco: with ``partial``
    > 0 a random share up to that fraction is dropped per view), plus N(0, noise_px) per
    coordinate. ``flip_symmetric``: reverse the corner order of a random half of the views (what
    findChessboardCorners may do with a symmetric board); they are returned as ``flipped``."""
    obj = board.object_points()
    dets, flipped = {}, set()
    names = []
    for k, (R, t) in enumerate(poses):
        pose = f"pose_{k + 1:03d}"
        names.append(pose)
        X = obj @ R.T + t
        for cam in rig.cameras:
            uv, z = cam.project(X)
            ok = (z > 0.05) & cam.in_image(uv, margin=3)
            ids = np.flatnonzero(ok)
            if board.type == "chessboard":
                if not ok.all():
                    continue
                ids = None
                pts = uv
            else:
                if partial > 0:
                    keep = rng.uniform(size=len(ids)) > rng.uniform(0, partial)
                    ids = ids[keep]
                if len(ids) < 6:
                    continue
                pts = uv[ids]
            pts = pts + rng.normal(0, noise_px, pts.shape)
            if flip_symmetric and board.is_symmetric and rng.uniform() < 0.5:
                pts = pts[::-1]
                flipped.add((pose, cam.name))
            dets[(pose, cam.name)] = Detection(pose, cam.name, FOUND, "", pts.astype(np.float32),
                                               None if ids is None else ids.astype(np.int32),
                                               (cam.width, cam.height), False)
    session = Session(Path(folder), board, {c.name: c.modality for c in rig.cameras}, rig.depth_camera,
                      rig.depth_scale, [], {})
    return session, dets, flipped


def true_projection_errors(cal, truth: Rig, cam: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """At the grid of ``cal.uncertainty[cam]``: the true error (px) of the calibrated lens model
    (the point in the camera's frame) and of the calibrated camera in the rig (the point fixed in
    the rig frame), with the reported sigmas: (err_intrinsics, sigma_intrinsics, err_rig,
    sigma_rig), each (H, W)."""
    u = cal.uncertainty[cam]
    est, tru = cal.rig.camera(cam), truth.camera(cam)
    X_cam = _grid_points(u, est)
    q_i = cv2.projectPoints(X_cam, np.zeros(3), np.zeros(3), tru.K, tru.dist)[0].reshape(-1, 2)
    uv = _grid_uv(u)
    e_i = np.linalg.norm(q_i - uv, axis=1).reshape(u.sigma_intrinsics.shape)
    X_rig = est.to_rig(X_cam)
    q_r, _z = tru.project(X_rig)
    e_r = np.linalg.norm(q_r - uv, axis=1).reshape(u.sigma_intrinsics.shape)
    return e_i, u.sigma_intrinsics, e_r, u.sigma_rig


def _grid_uv(u) -> np.ndarray:
    uu, vv = np.meshgrid(u.grid_u, u.grid_v)
    return np.c_[uu.ravel(), vv.ravel()]


def _grid_points(u, est: Camera, factor: float = 1.0) -> np.ndarray:
    xy = est.undistort_normalized(_grid_uv(u))
    return np.c_[xy, np.ones(len(xy))] * u.distance_m * factor


def true_among_boards_errors(cal, truth: Rig, cam: str, poses, factor: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """mrcal's "mean frames" truth: each grid point at ``factor`` x the working distance, put on
    every estimated board, carried to the same place on the true board (``poses``: the true
    (R_rig_board, t_rig_board) of pose_001, pose_002, ...), averaged and projected by the true
    camera. (err (H, W) px, the reported ``sigma_boards_at[factor]``)."""
    u = cal.uncertainty[cam]
    est, tru = cal.rig.camera(cam), truth.camera(cam)
    X_rig = est.to_rig(_grid_points(u, est, factor))
    X_true = np.zeros_like(X_rig)
    for p, (Re, te) in cal.board_poses.items():
        Rt, tt = poses[int(p.split("_")[1]) - 1]
        X_true += ((X_rig - te) @ Re) @ Rt.T + tt
    q, _z = tru.project(X_true / len(cal.board_poses))
    e = np.linalg.norm(q - _grid_uv(u), axis=1).reshape(u.sigma_boards.shape)
    return e, u.sigma_boards_at[factor]
