"""Intrinsics per camera and one joint estimate of the whole rig.

1. *Intrinsics*: ``cv2.calibrateCamera`` per camera on its usable views (found, not excluded),
   5 distortion coefficients (k3 fixed with fewer than 6 views; the 8-coefficient rational model
   when it fits clearly better). Per-view errors = mean distance between projected and detected
   corners with the view's own board pose.
2. *Initial extrinsics*: for every camera, the relative pose to an already placed camera from
   each shared pose (``R_cam_ref = R_cam_board R_board_ref``); the medoid over the shared poses
   (robust to a bad view); cameras are placed breadth-first from the reference (the depth camera,
   else the first camera). A camera sharing no pose with the placed ones is an error.
3. *Joint refinement*: one bundle adjustment (``scipy.optimize.least_squares``, analytic
   Jacobian from ``cv2.projectPoints`` chained through ``cv2.composeRT``, soft-L1 loss that is
   quadratic below 1 px) over all cameras' intrinsics and poses and all board poses, minimising
   the reprojection error of every used corner in every camera. (OpenCV 5's
   ``calibrateMultiview`` needs every point of every frame; ours also takes partial ChArUco views.)

Weak views: a view whose intrinsic error exceeds ``max(2 x median, median + 0.1 px)`` of its
camera, or whose board pose disagrees with the rig by more than 1 degree (a flipped corner order
gives ~180), is listed with its numbers in ``weak_views`` -- never dropped: the caller decides.
The one exception is a view whose board pose disagrees with the other cameras' by more than 5
degrees before the joint refinement: it would drag the whole rig, so it is left out of the joint
estimate (not of the intrinsics) and listed first among the weak views, saying so.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np

from ..camera.camera import Camera
from ..errors import InputError
from ..progress import Reporter, ensure_reporter
from ..camera.rig import Rig
from .board import Board
from .detect import FOUND, MISSING, Detection, check_image_sizes, suggest_board_size
from .session import Session

MIN_VIEWS = 3
#: A calibration whose joint RMS reprojection error, or one camera's, exceeds this many pixels
#: has failed (a wrong board size gives ~9 px; good rigs 0.05-0.5 px): ``plantreg calibrate``
#: writes nothing and exits non-zero unless ``--max-rms`` allows more (docs/errors.md).
MAX_RMS_PX = 2.0
WEAK_FACTOR, WEAK_MIN_EXCESS_PX, WEAK_POSE_DEG = 2.0, 0.1, 1.0
INCONSISTENT_DEG = 5.0


@dataclass
class CameraCalibration:
    """Intrinsics of one camera. ``rms_px`` RMS reprojection error of the final model (each view
    with its own board pose, OpenCV's definition);
    ``mean_px`` mean corner distance; ``per_view_px`` pose -> mean corner distance (px) with the
    view's own board pose; ``weak_views`` [(pose, px, reason)] worst first."""

    name: str
    modality: str
    width: int
    height: int
    K: np.ndarray
    dist: np.ndarray
    rms_px: float
    mean_px: float
    per_view_px: dict[str, float]
    weak_views: list[tuple[str, float, str]] = field(default_factory=list)
    n_views: int = 0

    @property
    def normalization(self) -> float:
        return 1000.0 / float(np.sqrt(self.width * self.height))

    def to_dict(self) -> dict[str, Any]:
        return {"K": self.K.tolist(), "dist": self.dist.tolist(), "rms_px": self.rms_px, "mean_px": self.mean_px,
                "n_views": self.n_views, "per_view_px": self.per_view_px,
                "weak_views": [{"pose": p, "px": e, "reason": r} for p, e, r in self.weak_views]}


@dataclass
class Calibration:
    """The result: ``rig`` (cameras in the reference camera's frame = the depth camera's if any),
    ``intrinsics`` per camera, ``board_poses`` pose -> (R_rig_board (3, 3), t_rig_board (3,)),
    ``used_views`` [(pose, camera)], ``joint_rms_px`` of the bundle adjustment,
    ``view_pose_deg`` (pose, camera) -> angle between the view's own board pose and the rig's."""

    rig: Rig
    board: Board
    intrinsics: dict[str, CameraCalibration]
    board_poses: dict[str, tuple[np.ndarray, np.ndarray]]
    used_views: list[tuple[str, str]]
    joint_rms_px: float
    reference: str
    view_pose_deg: dict[tuple[str, str], float] = field(default_factory=dict)
    view_board_cam: dict[tuple[str, str], tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)
    #: (pose, camera) -> mean corner distance (px) of a view *excluded* by the user, measured with
    #: the final intrinsics and the view's own board pose (as ``per_view_px``), so that an
    #: exclusion can be judged; views whose board was not found are absent.
    excluded_px: dict[tuple[str, str], float] = field(default_factory=dict)

    @property
    def weak_views(self) -> list[tuple[str, str, float, str]]:
        """All weak views, worst first (inconsistent board poses, then by error): (pose, camera, px, reason)."""
        out = [(p, c.name, e, r) for c in self.intrinsics.values() for p, e, r in c.weak_views]
        return sorted(out, key=lambda x: (-("disagrees" in x[3]), -x[2]))

    def provenance(self) -> dict[str, Any]:
        return {
            "reference": self.reference,
            "joint_rms_px": self.joint_rms_px,
            "used_views": [f"{p}:{c}" for p, c in self.used_views],
            "cameras": {n: {"rms_px": c.rms_px, "mean_px": c.mean_px,
                            "mean_normalized": c.mean_px * c.normalization, "n_views": c.n_views,
                            "weak_views": [f"{p}:{n} {e:.3f} px ({r})" for p, e, r in c.weak_views]}
                        for n, c in self.intrinsics.items()},
        }


# ---------------------------------------------------------------------- small geometry helpers
def _angle_deg(R: np.ndarray) -> float:
    return float(np.degrees(np.arccos(np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0))))


def _medoid_pose(cands: list[tuple[np.ndarray, np.ndarray]]) -> tuple[np.ndarray, np.ndarray]:
    """The candidate pose closest (rotation angle + translation) to all others."""
    if len(cands) == 1:
        return cands[0]
    best, best_cost = cands[0], np.inf
    for Ra, ta in cands:
        cost = float(np.median([_angle_deg(Ra @ Rb.T) for Rb, _ in cands]))
        cost += 10.0 * float(np.median([np.linalg.norm(ta - tb) for _, tb in cands]))
        if cost < best_cost:
            best, best_cost = (Ra, ta), cost
    return best


def _view_points(det: Detection, board: Board) -> tuple[np.ndarray, np.ndarray]:
    return det.object_points(board).astype(np.float64), det.corners.astype(np.float64)


# ---------------------------------------------------------------------- intrinsics
def _calibrate_intrinsics(name: str, views: dict[str, Detection], board: Board, size: tuple[int, int]):
    """``cv2.calibrateCamera`` with 5 coefficients (k3 fixed below 6 views); with 8 or more views
    also the rational model (8 coefficients, as wide-angle ToF cameras need), kept only if it
    lowers the RMS error by more than 10 %. Returns K, dist, {pose: (R_cam_board, t)}, flags."""
    poses = sorted(views)
    obj = [_view_points(views[p], board)[0].astype(np.float32) for p in poses]
    img = [views[p].corners.reshape(-1, 1, 2).astype(np.float32) for p in poses]
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-10)
    candidates = [0 if len(poses) >= 6 else cv2.CALIB_FIX_K3]
    if len(poses) >= 8:
        candidates.append(cv2.CALIB_RATIONAL_MODEL)
    best = None
    for flags in candidates:
        try:
            rms, K, dist, rvecs, tvecs = cv2.calibrateCamera(obj, img, size, None, None, flags=flags, criteria=crit)
        except cv2.error as e:
            if best is not None:
                continue
            raise InputError(f"camera '{name}': OpenCV could not calibrate it ({str(e).strip().splitlines()[-1]})") from None
        if best is None or rms < 0.9 * best[0]:
            nd = 8 if flags & cv2.CALIB_RATIONAL_MODEL else 5
            best = (rms, K, dist.ravel()[:nd].copy(), rvecs, tvecs, flags)
    rms, K, dist, rvecs, tvecs, flags = best
    board_cam = {p: (cv2.Rodrigues(rv)[0], tv.ravel()) for p, rv, tv in zip(poses, rvecs, tvecs)}
    return K, dist, board_cam, flags


def _per_view_errors(K, dist, views: dict[str, Detection], board: Board,
                     init: dict[str, tuple[np.ndarray, np.ndarray]] | None = None):
    """Mean corner distance per view with the view's own board pose (PnP with the final model).
    Returns {pose: px}, {pose: (R_cam_board, t)}, {pose: residual vectors (N, 2)}, rms."""
    out, poses, resid = {}, {}, {}
    sq = []
    for p, d in views.items():
        obj, img = _view_points(d, board)
        if init and p in init:
            rv0 = cv2.Rodrigues(init[p][0])[0]
            ok, rv, tv = cv2.solvePnP(obj, img, K, dist, rv0.copy(), init[p][1].reshape(3, 1).copy(), True)
        else:
            ok, rv, tv = cv2.solvePnP(obj, img, K, dist)
        rv, tv = cv2.solvePnPRefineLM(obj, img, K, dist, rv, tv)
        proj = cv2.projectPoints(obj, rv, tv, K, dist)[0].reshape(-1, 2)
        r = proj - img
        out[p] = float(np.mean(np.linalg.norm(r, axis=1)))
        poses[p] = (cv2.Rodrigues(rv)[0], tv.ravel())
        resid[p] = r
        sq.append(np.sum(r**2, axis=1))
    rms = float(np.sqrt(np.mean(np.concatenate(sq)))) if sq else float("nan")
    return out, poses, resid, rms


# ---------------------------------------------------------------------- joint bundle adjustment
def _pack_cam(K, dist, R, t):
    return np.concatenate([[K[0, 0], K[1, 1], K[0, 2], K[1, 2]], dist, cv2.Rodrigues(R)[0].ravel(), t])


def _unpack_cam(x, nd: int):
    K = np.array([[x[0], 0, x[2]], [0, x[1], x[3]], [0, 0, 1.0]])
    return K, x[4 : 4 + nd], x[4 + nd : 7 + nd], x[7 + nd : 10 + nd]


def _bundle_adjust(cams: list[str], ref: str, init_cam: dict[str, tuple], init_board: dict[str, tuple],
                   obs: list[tuple[str, str, np.ndarray, np.ndarray]], fix_k3: dict[str, bool],
                   progress: Reporter) -> tuple[dict[str, tuple], dict[str, tuple], float]:
    """One joint least-squares fit of all intrinsics, camera poses and board poses.

    init_cam: cam -> (K, dist (5,) or (8,), R_cam_rig, t_cam_rig); init_board: pose ->
    (R_rig_board, t_rig_board); obs: (pose, cam, obj (N, 3), img (N, 2)). The reference camera's
    pose stays the identity (it defines the rig frame)."""
    poses = sorted(init_board)
    pi = {p: i for i, p in enumerate(poses)}
    nd = {c: len(init_cam[c][1]) for c in cams}
    off, o = {}, 0
    for c in cams:
        off[c] = o
        o += 10 + nd[c]
    x0 = np.concatenate([_pack_cam(*init_cam[c]) for c in cams]
                        + [np.concatenate([cv2.Rodrigues(init_board[p][0])[0].ravel(), init_board[p][1]]) for p in poses])
    nb0 = o
    # free-parameter mask: the reference camera's pose is the rig frame; k3 fixed where asked
    free = np.ones_like(x0, bool)
    free[off[ref] + 4 + nd[ref] : off[ref] + 10 + nd[ref]] = False
    for c in cams:
        if fix_k3.get(c):
            free[off[c] + 8] = False
    idx_free = np.flatnonzero(free)
    n_res = sum(2 * len(o[2]) for o in obs)

    def full(xf):
        x = x0.copy()
        x[idx_free] = xf
        return x

    nfree = len(idx_free)
    col_of = -np.ones(len(x0), int)
    col_of[idx_free] = np.arange(nfree)

    def evaluate(xf, want_jac: bool):
        # analytic Jacobian: projectPoints' derivatives chained through composeRT
        progress.check()  # a cancellation point inside the solver
        x = full(xf)
        out = np.empty(n_res)
        J = np.zeros((n_res, nfree)) if want_jac else None
        k = 0
        for pose, cam, obj, img in obs:
            c0, n_d = off[cam], nd[cam]
            K, dist, rvc, tc = _unpack_cam(x[c0 : c0 + 10 + n_d], n_d)
            b = nb0 + 6 * pi[pose]
            rv, tv, dr3dr1, dr3dt1, dr3dr2, dr3dt2, dt3dr1, dt3dt1, dt3dr2, dt3dt2 = cv2.composeRT(
                x[b : b + 3], x[b + 3 : b + 6], rvc, tc)
            proj, jac = cv2.projectPoints(obj, rv, tv, K, dist)
            r = (proj.reshape(-1, 2) - img).ravel()
            n = len(r)
            out[k : k + n] = r
            if want_jac:
                Jr, Jt = jac[:, 0:3], jac[:, 3:6]
                cols_cam = np.concatenate([jac[:, 6:10], jac[:, 10 : 10 + n_d],
                                           Jr @ dr3dr2 + Jt @ dt3dr2, Jr @ dr3dt2 + Jt @ dt3dt2], axis=1)
                cols_board = np.concatenate([Jr @ dr3dr1 + Jt @ dt3dr1, Jr @ dr3dt1 + Jt @ dt3dt1], axis=1)
                for j in range(10 + n_d):
                    cj = col_of[c0 + j]
                    if cj >= 0:
                        J[k : k + n, cj] = cols_cam[:, j]
                for j in range(6):
                    cj = col_of[b + j]
                    if cj >= 0:
                        J[k : k + n, cj] = cols_board[:, j]
            k += n
        return out, J

    def residuals(xf):
        return evaluate(xf, False)[0]

    def jacobian(xf):
        return evaluate(xf, True)[1]

    progress(0.1, "joint refinement of all cameras and board poses")
    from scipy.optimize import least_squares  # here: importing it costs ~1 s at GUI start-up

    # soft-L1 loss (quadratic below 1 px): one misdetected view must not drag the whole rig
    sol = least_squares(residuals, x0[idx_free], jac=jacobian, method="trf", loss="soft_l1", f_scale=1.0,
                        x_scale="jac", xtol=1e-10, ftol=1e-10, gtol=1e-10, max_nfev=100)
    progress(0.95, "joint refinement done")
    x = full(sol.x)
    out_cam = {}
    for c in cams:
        K, dist, rv, t = _unpack_cam(x[off[c] : off[c] + 10 + nd[c]], nd[c])
        out_cam[c] = (K, dist.copy(), cv2.Rodrigues(rv)[0], t.copy())
    out_board = {p: (cv2.Rodrigues(x[nb0 + 6 * pi[p] : nb0 + 6 * pi[p] + 3])[0], x[nb0 + 6 * pi[p] + 3 : nb0 + 6 * pi[p] + 6].copy())
                 for p in poses}
    rms = float(np.sqrt(np.mean(sol.fun**2) * 2)) if len(sol.fun) else float("nan")
    return out_cam, out_board, rms


# ---------------------------------------------------------------------- main entry
def usable_views(session: Session, detections: dict[tuple[str, str], Detection],
                 excluded: set[tuple[str, str]] | frozenset = frozenset()) -> dict[str, dict[str, Detection]]:
    """camera -> {pose: detection} of found, not excluded views."""
    out: dict[str, dict[str, Detection]] = {c: {} for c in session.cameras}
    for (pose, cam), d in detections.items():
        if cam in out and d.status == FOUND and (pose, cam) not in excluded and d.corners is not None:
            if session.board.type == "charuco" and len(d.corners) < 6:
                continue
            out[cam][pose] = d
    return out


def _too_few_message(session: Session, cam: str, views: dict[str, Detection],
                     detections: dict[tuple[str, str], Detection], excluded) -> str:
    mine = {p: d for (p, c), d in detections.items() if c == cam and d.status != MISSING}
    failed = [d for d in mine.values() if d.status == "failed"]
    n_ex = sum(1 for (p, c) in excluded if c == cam)
    msg = (f"camera '{cam}': only {len(views)} usable board pose(s), at least {MIN_VIEWS} are needed "
           f"({len(mine)} images, {len(failed)} without a board, {n_ex} excluded)")
    if not mine:
        msg += f". No pose folder has an image named after the camera ('{cam}.png', '{cam}.tif', ...)"
    if not views and failed and session.board.type == "chessboard":
        from ..io.imageio import read_image

        imgs = []
        for d in failed[:3]:
            if d.path is not None:
                try:
                    imgs.append(read_image(d.path))
                except InputError:
                    pass
        sug = suggest_board_size(imgs, session.board) if imgs else None
        if sug:
            msg += (f". No {session.board.columns}x{session.board.rows} board was found, but a {sug[0]}x{sug[1]} one "
                    f"was: set columns={sug[0]}, rows={sug[1]} (count inner corners, where four squares meet)")
        else:
            msg += f". First failure: {failed[0].path}: {failed[0].reason}"
    return msg


def quality_problems(cal: "Calibration", max_rms_px: float = MAX_RMS_PX) -> list[str]:
    """Why ``cal`` has clearly failed (empty list: it has not): RMS errors above ``max_rms_px``
    (joint and per camera), or a calibrated camera outside the rig sanity bounds
    (:mod:`plantreg_gui.core.validate`). Each item is one sentence with the numbers."""
    out = []
    if not np.isfinite(cal.joint_rms_px) or cal.joint_rms_px > max_rms_px:
        out.append(f"joint RMS reprojection error {cal.joint_rms_px:.2f} px exceeds {max_rms_px:g} px")
    for name, c in cal.intrinsics.items():
        if not np.isfinite(c.rms_px) or c.rms_px > max_rms_px:
            out.append(f"camera '{name}': RMS error {c.rms_px:.2f} px exceeds {max_rms_px:g} px "
                       f"(fx {c.K[0, 0]:.1f}, fy {c.K[1, 1]:.1f} px)")
    for i, c in enumerate(cal.rig.cameras):
        try:
            Camera.from_dict(c.to_dict(), f"camera '{c.name}'")
        except ValueError as e:
            out.append(f"the calibrated {e}")
    return out


def calibrate(session: Session, detections: dict[tuple[str, str], Detection],
              excluded: set[tuple[str, str]] | frozenset = frozenset(),
              progress: Reporter | None = None) -> Calibration:
    """Calibrate every camera of ``session`` from ``detections`` ((pose, camera) -> Detection),
    leaving out ``excluded`` views. Raises :class:`InputError` for images of different sizes
    for one camera, a camera with fewer than 3 usable poses, or one sharing no pose with the
    others."""
    progress = ensure_reporter(progress)
    board = session.board
    sizes = check_image_sizes(session, detections)
    views = usable_views(session, detections, excluded)
    for cam in session.cameras:
        if len(views[cam]) < MIN_VIEWS:
            raise InputError(_too_few_message(session, cam, views[cam], detections, excluded), session.folder)
    cams = list(session.cameras)
    ref = session.depth_camera or cams[0]

    # 1. intrinsics per camera
    intr: dict[str, Any] = {}
    with progress.stage("intrinsics", 0.0):
        for i, cam in enumerate(cams):
            progress(0.3 * i / len(cams), f"intrinsics of {cam} ({len(views[cam])} views)")
            intr[cam] = _calibrate_intrinsics(cam, views[cam], board, sizes[cam])

    # 2. initial extrinsics, breadth-first from the reference
    placed: dict[str, tuple[np.ndarray, np.ndarray]] = {ref: (np.eye(3), np.zeros(3))}
    queue = deque([ref])
    while queue:
        a = queue.popleft()
        for b in cams:
            if b in placed:
                continue
            shared = sorted(set(views[a]) & set(views[b]))
            if not shared:
                continue
            Ra_rig, ta_rig = placed[a]
            cands = []
            for p in shared:
                Rab, tab = intr[a][2][p]  # board in a
                Rbb, tbb = intr[b][2][p]  # board in b
                R_b_a = Rbb @ Rab.T
                t_b_a = tbb - R_b_a @ tab
                cands.append((R_b_a @ Ra_rig, R_b_a @ ta_rig + t_b_a))
            placed[b] = _medoid_pose(cands)
            queue.append(b)
    missing = [c for c in cams if c not in placed]
    if missing:
        c = missing[0]
        others = sorted({p for o in placed for p in views[o]})
        raise InputError(
            f"camera '{c}' shares no board pose with {', '.join(sorted(placed))}: it saw the board in "
            f"{', '.join(sorted(views[c]))}, the others in {', '.join(others)}. Record poses in which "
            f"'{c}' and another camera see the board at the same time", session.folder)
    progress(0.35, "initial extrinsics")

    # board poses in the rig frame: the medoid of what the cameras that saw the pose say. A view
    # disagreeing with it by more than INCONSISTENT_DEG (e.g. a corner order flipped by 180
    # degrees) is left out of the joint estimate and reported, never used silently.
    all_poses = sorted({p for c in cams for p in views[c]})
    init_board, outliers = {}, {}
    for p in all_poses:
        preds = {}
        for c in [ref] + [c for c in cams if c != ref]:
            if p in views[c]:
                Rc, tc = placed[c]
                Rcb, tcb = intr[c][2][p]
                preds[c] = (Rc.T @ Rcb, Rc.T @ (tcb - tc))
        init_board[p] = _medoid_pose(list(preds.values())) if len(preds) > 2 else next(iter(preds.values()))
        for c, (Rp, _tp) in preds.items():
            ang = _angle_deg(Rp @ init_board[p][0].T)
            if ang > INCONSISTENT_DEG:
                outliers[(p, c)] = ang

    # 3. joint refinement
    obs = [(p, c, *_view_points(views[c][p], board)) for c in cams for p in sorted(views[c]) if (p, c) not in outliers]
    init_cam = {c: (intr[c][0], intr[c][1], *placed[c]) for c in cams}
    fix_k3 = {c: bool(intr[c][3] & cv2.CALIB_FIX_K3) for c in cams}
    with progress.stage("joint refinement", 0.35):
        cam_res, board_res, joint_rms = _bundle_adjust(cams, ref, init_cam, init_board, obs, fix_k3, progress.sub(0.35, 0.85))

    # 4. per-view errors and weak views
    intrinsics: dict[str, CameraCalibration] = {}
    view_pose_deg: dict[tuple[str, str], float] = {}
    view_board_cam: dict[tuple[str, str], tuple[np.ndarray, np.ndarray]] = {}
    cameras = []
    for cam in cams:
        K, dist, R, t = cam_res[cam]
        init = {p: (R @ board_res[p][0], R @ board_res[p][1] + t) for p in views[cam]}
        per_view, own_poses, resid, rms = _per_view_errors(
            K, dist, views[cam], board, {p: v for p, v in init.items() if (p, cam) not in outliers})
        allr = np.concatenate([np.linalg.norm(r, axis=1) for r in resid.values()])
        weak = []
        med = float(np.median(list(per_view.values())))
        for p, e in per_view.items():
            Rown = own_poses[p][0]
            ang = _angle_deg(Rown @ init[p][0].T)
            view_pose_deg[(p, cam)] = ang
            view_board_cam[(p, cam)] = own_poses[p]
            if (p, cam) in outliers or ang > WEAK_POSE_DEG:
                weak.append((p, e, f"board pose disagrees with the other cameras by {ang:.1f} deg"
                             + (" (corner order flipped? check the polarity)" if ang > 150 else "")
                             + ("; left out of the joint estimate" if (p, cam) in outliers else "")))
            elif e > max(WEAK_FACTOR * med, med + WEAK_MIN_EXCESS_PX):
                weak.append((p, e, f"error {e:.3f} px is {e / med:.1f}x the median {med:.3f} px"))
        weak.sort(key=lambda w: (-("disagrees" in w[2]), -w[1]))
        w, h = sizes[cam]
        intrinsics[cam] = CameraCalibration(cam, session.cameras[cam], w, h, K, dist, rms, float(allr.mean()),
                                            dict(sorted(per_view.items())), weak, len(per_view))
        cameras.append(Camera(cam, session.cameras[cam], w, h, K, dist, R, t))
    rig = Rig(cameras, session.depth_camera, session.depth_scale)
    progress(1.0, "calibration done")
    used = sorted((p, c) for c in cams for p in views[c] if (p, c) not in outliers)
    return Calibration(rig, board, intrinsics, board_res, used, joint_rms, ref, view_pose_deg, view_board_cam,
                       excluded_view_errors(intrinsics, session, detections, excluded))


def excluded_view_errors(intrinsics: dict[str, "CameraCalibration"], session: Session,
                         detections: dict[tuple[str, str], Detection], excluded) -> dict[tuple[str, str], float]:
    """Mean corner distance (px) of each excluded view whose board was found, with the camera's
    calibrated model and the view's own board pose (PnP)."""
    out: dict[tuple[str, str], float] = {}
    board = session.board
    for key in sorted(excluded):
        d, cc = detections.get(key), intrinsics.get(key[1])
        if d is None or cc is None or d.status != FOUND or d.corners is None or len(d.corners) < 4:
            continue
        try:
            per_view = _per_view_errors(cc.K, cc.dist, {key[0]: d}, board)[0]
        except cv2.error:
            continue
        out[key] = per_view[key[0]]
    return out
