"""Intrinsics per camera and one joint estimate of the whole rig.

1. *Intrinsics*: per camera on its usable views (found, not excluded), the lens model chosen by
   leave-views-out cross-validation (:mod:`.lensmodel`), fitted with ``cv2.calibrateCamera``.
   Cameras with given intrinsics (``known``: ``--intrinsics CAM=RIG.json`` or ``"intrinsics"`` in
   session.json) keep them (fixed, or as priors with their standard errors). Per-view errors =
   mean distance between projected and detected corners with the view's own board pose.
2. *Initial extrinsics*: cameras are placed one at a time (the reference first: the depth camera,
   else the first camera; then the camera sharing most board poses with those placed), each from
   the board poses already known in the rig frame (``R_cam_rig = R_cam_board R_board_rig``), the
   medoid over the shared poses (robust to a bad view). A symmetric board (it looks the same
   turned by 180 degrees, so the detector's corner order is arbitrary per view) is resolved here:
   both orders of every view are candidates, the pose most board poses agree with wins, and each
   view keeps the order consistent with it (``Calibration.flipped``); a board pose seen by one
   camera keeps that camera's order. A camera sharing no pose with the placed ones is an error.
3. *Joint refinement*: one bundle adjustment (:mod:`.bundle`: Levenberg-Marquardt on the sparse
   normal equations, Schur complement over the board poses, soft-L1 loss quadratic below 1 px)
   over all cameras' intrinsics and poses and all board poses, minimising the reprojection error
   of every used corner in every camera. (OpenCV 5's ``calibrateMultiview`` needs every point of
   every frame; ours also takes partial ChArUco views.) Its covariance gives every parameter's
   standard error and each camera's projection uncertainty (:mod:`.uncertainty`).

Length: one pipeline (intrinsics, placement with the symmetric-board resolution, joint fit,
per-view errors) whose steps share the views, their corner orders and the placed poses; the
solver's parts that stand alone live beside it (:mod:`.bundle`, :mod:`.lensmodel`,
:mod:`.uncertainty`, :mod:`.known`).

Weak views: a view whose intrinsic error exceeds ``max(2 x median, median + 0.1 px)`` of its
camera, or whose board pose disagrees with the rig by more than 1 degree (a flipped corner order
gives ~180), is listed with its numbers in ``weak_views`` -- never dropped: the caller decides.
The one exception is a view whose board pose disagrees with the other cameras' by more than 5
degrees before the joint refinement: it would drag the whole rig, so it is left out of the joint
estimate (not of the intrinsics) and listed first among the weak views, saying so.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from ..camera.camera import Camera
from ..errors import InputError
from ..progress import Reporter, ensure_reporter
from ..camera.rig import Rig
from .board import Board
from .bundle import DIST_NAMES, CameraBlock, bundle_adjust, param_names
from .known import KnownIntrinsics, check_known_intrinsics, load_known_intrinsics, session_known_intrinsics
from .lensmodel import MODEL_BY_NAME, ModelChoice, choose_model, fit_camera, focal_rel_std, principal_point_prior
from .uncertainty import (MAX_PROJECTION_SIGMA_COVERED, MAX_PROJECTION_SIGMA_MEDIAN, MAX_TRANSLATION_SIGMA_MM,
                          CameraUncertainty, plane_spread_deg, projection_uncertainty, uncertainty_problems)
from .detect import FOUND, MISSING, Detection, check_image_sizes, suggest_board_size
from .session import Session

MIN_VIEWS = 3
#: fewer views than this leave the lens model unchecked (no cross-validation): refused as uncertain
MIN_CV_VIEWS = 4
#: A calibration whose joint RMS reprojection error, or one camera's, exceeds this many pixels
#: has failed (a wrong board size gives ~9 px; good rigs 0.05-0.5 px): ``plantreg calibrate``
#: writes nothing and exits non-zero unless ``--max-rms`` allows more (docs/errors.md).
MAX_RMS_PX = 2.0
WEAK_FACTOR, WEAK_MIN_EXCESS_PX, WEAK_POSE_DEG = 2.0, 0.1, 1.0
#: a view's board pose is weak when it disagrees with the rig by more than this many standard
#: errors of its own pose (and more than WEAK_POSE_DEG)
WEAK_POSE_SIGMAS = 3.0
INCONSISTENT_DEG = 5.0
#: relative standard error of a camera's focal length from its own views above which its own
#: views are taken not to determine its lens (placed last, from the board corners in 3D)
UNDETERMINED_FOCAL = 0.02


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
    #: the lens model chosen by cross-validation (None: intrinsics given, see ``known``)
    model: ModelChoice | None = None
    known: KnownIntrinsics | None = None

    @property
    def normalization(self) -> float:
        return 1000.0 / float(np.sqrt(self.width * self.height))

    def to_dict(self) -> dict[str, Any]:
        return {"K": self.K.tolist(), "dist": self.dist.tolist(), "rms_px": self.rms_px, "mean_px": self.mean_px,
                "n_views": self.n_views, "per_view_px": self.per_view_px,
                "weak_views": [{"pose": p, "px": e, "reason": r} for p, e, r in self.weak_views],
                "lens_model": self.lens_model_dict()}

    def lens_model_dict(self) -> dict[str, Any]:
        if self.known is not None:
            return {"model": "given", "source": self.known.source,
                    "reason": "intrinsics given" + (" as priors with their standard errors" if self.known.std
                                                    else ", held fixed")}
        return self.model.to_dict() if self.model is not None else {}


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
    #: camera -> its uncertainty (standard errors, projection uncertainty; :mod:`.uncertainty`)
    uncertainty: dict[str, CameraUncertainty] = field(default_factory=dict)
    #: (pose, camera) views of a symmetric board whose detected corner order was reversed to
    #: agree with the rig (the board looks the same turned by 180 degrees)
    flipped: set[tuple[str, str]] = field(default_factory=set)
    #: residual standard deviation per corner coordinate of the joint fit (px)
    sigma_px: float = float("nan")
    #: camera -> its corner noise per coordinate in the joint fit (px): its residuals' weight
    noise_px: dict[str, float] = field(default_factory=dict)
    #: set when the calibration was kept although its uncertainty exceeds the limits
    accepted_uncertain: list[str] = field(default_factory=list)

    @property
    def weak_views(self) -> list[tuple[str, str, float, str]]:
        """All weak views, worst first (inconsistent board poses, then by error): (pose, camera, px, reason)."""
        out = [(p, c.name, e, r) for c in self.intrinsics.values() for p, e, r in c.weak_views]
        return sorted(out, key=lambda x: (-("disagrees" in x[3]), -x[2]))

    def provenance(self) -> dict[str, Any]:
        out = {
            "reference": self.reference,
            "joint_rms_px": self.joint_rms_px,
            "residual_sigma_px": self.sigma_px,
            "used_views": [f"{p}:{c}" for p, c in self.used_views],
            "flipped_views": sorted(f"{p}:{c}" for p, c in self.flipped),
            "uncertainty_limits": {"projection_sigma_median_px_or_diagonal": list(MAX_PROJECTION_SIGMA_MEDIAN),
                                   "projection_sigma_where_seen_px_or_diagonal": list(MAX_PROJECTION_SIGMA_COVERED),
                                   "rig_projection_sigma_median_px_or_diagonal": list(MAX_PROJECTION_SIGMA_MEDIAN),
                                   "translation_sigma_mm": MAX_TRANSLATION_SIGMA_MM},
            "cameras": {n: {"rms_px": c.rms_px, "mean_px": c.mean_px,
                            "mean_normalized": c.mean_px * c.normalization, "n_views": c.n_views,
                            "weak_views": [f"{p}:{n} {e:.3f} px ({r})" for p, e, r in c.weak_views],
                            "lens_model": c.lens_model_dict()}
                        for n, c in self.intrinsics.items()},
        }
        for n, u in self.uncertainty.items():
            d = u.to_dict()
            d.pop("grid")
            out["cameras"][n]["uncertainty"] = d
        if self.accepted_uncertain:
            out["accepted_uncertain"] = self.accepted_uncertain
        return out

    def uncertainty_problems(self) -> list[str]:
        """Cameras and poses whose uncertainty exceeds the documented limits, and cameras with too
        few views to check their lens model against views it was not fitted to (one sentence
        each): the standard errors hold only for a model the views support."""
        out = []
        for name, c in self.intrinsics.items():
            if c.model is not None and c.model.n_folds == 0 and c.n_views < MIN_CV_VIEWS:
                out.append(f"camera '{name}': only {c.n_views} views, too few to check its lens model against "
                           f"views it was not fitted to (at least {MIN_CV_VIEWS}); record more board views, tilted, "
                           "all over its image")
        return out + uncertainty_problems(self.uncertainty)


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
    """The camera's lens model chosen by cross-validation (:mod:`.lensmodel`) and fitted to all
    its views. Returns K, dist, {pose: (R_cam_board, t)}, the :class:`~.lensmodel.ModelChoice`."""
    poses = sorted(views)
    obj = [_view_points(views[p], board)[0] for p in poses]
    img = [views[p].corners.reshape(-1, 2).astype(np.float64) for p in poses]
    choice, fit = choose_model(name, obj, img, size)
    rms, K, dist, fitted = fit
    board_cam = dict(zip(poses, fitted))
    choice.focal_rel_std = focal_rel_std(obj, img, choice.model, fit, size)
    return K, dist, board_cam, choice


def _known_intrinsics_poses(known: "KnownIntrinsics", views: dict[str, Detection], board: Board):
    """Board poses of a camera with given intrinsics (PnP per view)."""
    out = {}
    for p, d in sorted(views.items()):
        obj, img = _view_points(d, board)
        ok, rv, tv = cv2.solvePnP(obj, img, known.K, known.dist)
        rv, tv = cv2.solvePnPRefineLM(obj, img, known.K, known.dist, rv, tv)
        out[p] = (cv2.Rodrigues(rv)[0], tv.ravel())
    return out


def _per_view_errors(K, dist, views: dict[str, Detection], board: Board,
                     init: dict[str, tuple[np.ndarray, np.ndarray]] | None = None,
                     rot_sd: dict[str, float] | None = None):
    """Mean corner distance per view with the view's own board pose (PnP with the final model).
    Returns {pose: px}, {pose: (R_cam_board, t)}, {pose: residual vectors (N, 2)}, rms. With
    ``rot_sd`` (filled in): pose -> standard error (deg, per px of corner noise) of that own
    pose's rotation, from the Jacobian of its corners' projection."""
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
        proj, jac = cv2.projectPoints(obj, rv, tv, K, dist)
        proj = proj.reshape(-1, 2)
        r = proj - img
        if rot_sd is not None:
            J = jac[:, :6]
            try:
                cov = np.linalg.inv(J.T @ J)
                rot_sd[p] = float(np.degrees(np.sqrt(max(np.trace(cov[:3, :3]), 0.0))))
            except np.linalg.LinAlgError:
                rot_sd[p] = float("inf")
        out[p] = float(np.mean(np.linalg.norm(r, axis=1)))
        poses[p] = (cv2.Rodrigues(rv)[0], tv.ravel())
        resid[p] = r
        sq.append(np.sum(r**2, axis=1))
    rms = float(np.sqrt(np.mean(np.concatenate(sq)))) if sq else float("nan")
    return out, poses, resid, rms


# ---------------------------------------------------------------------- symmetric boards
def _pnp_pose(d: Detection, board: Board, K: np.ndarray, dist: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    obj, img = _view_points(d, board)
    ok, rv, tv = cv2.solvePnP(obj, img, K, dist)
    rv, tv = cv2.solvePnPRefineLM(obj, img, K, dist, rv, tv)
    return cv2.Rodrigues(rv)[0], tv.ravel()


def _calibrate_from_3d(cam: str, views: dict[str, Detection], shared: list[str],
                       board_rig: dict[str, tuple[np.ndarray, np.ndarray]], board: Board,
                       size: tuple[int, int], choice) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A camera whose own views do not determine its focal length, calibrated from the board
    corners of the poses already placed in the rig frame: together they are a non-planar target.
    Returns K, dist (in the chosen model's length), R_cam_rig, t_cam_rig."""
    X = np.concatenate([_view_points(views[p], board)[0] @ board_rig[p][0].T + board_rig[p][1] for p in shared])
    uv = np.concatenate([views[p].corners.astype(np.float64) for p in shared])
    w, h = size
    f0 = float(np.hypot(w, h))
    K0 = np.array([[f0, 0, (w - 1) / 2], [0, f0, (h - 1) / 2], [0, 0, 1.0]])
    model = choice.model if choice is not None else MODEL_BY_NAME["k1k2"]
    simple = MODEL_BY_NAME["k1k2"]
    rv, tv = cv2.solvePnP(X, uv, K0, np.zeros(5))[1:]
    fit = fit_camera([X], [uv], simple, K0, np.zeros(5), [(cv2.Rodrigues(rv)[0], tv.ravel())], size=size)
    if model is not simple:
        fit = fit_camera([X], [uv], model, fit[1], fit[2], fit[3], size=size)
    _rms, K, dist, poses = fit
    return K, dist, poses[0][0], poses[0][1]


def flip_pose(board: Board, R: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The board pose (R_x_board (3, 3), t (3,)) of a detection whose corner order is reversed
    (the board turned by 180 degrees about its centre's normal): corner k of the reversed order
    is board point ``Rz(180) X_k + d`` with ``d`` the far inner corner."""
    Rz = np.diag([-1.0, -1.0, 1.0])
    d = np.array([(board.columns - 1) * board.square_size, (board.rows - 1) * board.square_size, 0.0])
    return R @ Rz, R @ d + t


def flipped_detection(d: Detection) -> Detection:
    """The detection with its corner order reversed (a symmetric board seen turned by 180 degrees)."""
    return replace(d, corners=np.ascontiguousarray(d.corners[::-1]))


def oriented_views(views: dict[str, dict[str, Detection]], flipped) -> dict[str, dict[str, Detection]]:
    """``views`` (camera -> {pose: detection}) with the corner order of the ``flipped``
    (pose, camera) views reversed (see :attr:`Calibration.flipped`)."""
    if not flipped:
        return views
    return {c: {p: (flipped_detection(d) if (p, c) in flipped else d) for p, d in v.items()} for c, v in views.items()}


def _consensus(cands: list[tuple[str, int, np.ndarray, np.ndarray]]):
    """Among candidate camera poses [(pose, flip, R_cam_rig, t_cam_rig)] (two per board pose of
    a symmetric board, one per ordering), the one most board poses agree with (rotation within
    ``INCONSISTENT_DEG``), and per board pose the flip closest to it."""
    best, best_key = None, None
    Rs = np.stack([c[2] for c in cands])
    # angle between every two candidates at once: trace(Ri Rj^T) = sum of the elementwise product
    ang = np.degrees(np.arccos(np.clip((np.einsum("iab,jab->ij", Rs, Rs) - 1.0) / 2.0, -1.0, 1.0)))
    for i in range(len(cands)):
        angs: dict[str, float] = {}
        for j, (p, _f2, _Rj, _tj) in enumerate(cands):
            angs[p] = min(angs.get(p, np.inf), float(ang[i, j]))
        support = sum(a < INCONSISTENT_DEG for a in angs.values())
        key = (-support, float(np.median(list(angs.values()))))
        if best_key is None or key < best_key:
            best, best_key = i, key
    Rb = cands[best][2]
    chosen: dict[str, tuple[int, np.ndarray, np.ndarray]] = {}
    for p, f, R, t in cands:
        if p not in chosen or _angle_deg(R @ Rb.T) < _angle_deg(chosen[p][1] @ Rb.T):
            chosen[p] = (f, R, t)
    return chosen


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


def quality_problems(cal: "Calibration", max_rms_px: float = MAX_RMS_PX, report=None) -> list[str]:
    """Why ``cal`` has clearly failed (empty list: it has not): RMS errors above ``max_rms_px``
    (joint and per camera), a camera pair's epipolar error (``report.extrinsic``) above it -- each
    camera fits its own views, but the cameras disagree where the corners are (a stated board
    smaller than the real one, found at different offsets) -- or a calibrated camera outside the
    rig sanity bounds (:mod:`plantreg_gui.core.validate`). Each item is one sentence with the numbers."""
    out = []
    for o, row in (getattr(report, "extrinsic", None) or {}).items():
        for t, cell in (row or {}).items():
            if cell and o < t and not cell["px"] <= max_rms_px:
                out.append(f"cameras '{o}' and '{t}' disagree: epipolar error {cell['px']:.2f} px exceeds "
                           f"{max_rms_px:g} px")
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
              progress: Reporter | None = None,
              known: dict[str, KnownIntrinsics] | None = None) -> Calibration:
    """Calibrate every camera of ``session`` from ``detections`` ((pose, camera) -> Detection),
    leaving out ``excluded`` views. ``known`` camera -> intrinsics held fixed (or priors with
    their standard errors); default: the session's ``"intrinsics"`` entries. Raises
    :class:`InputError` for images of different sizes for one camera, a camera with fewer than 3
    usable poses, or one sharing no pose with the others."""
    progress = ensure_reporter(progress)
    board = session.board
    sizes = check_image_sizes(session, detections)
    known = dict(session_known_intrinsics(session) if known is None else known)
    check_known_intrinsics(session, known, sizes)
    views = usable_views(session, detections, excluded)
    for cam in session.cameras:
        if len(views[cam]) < MIN_VIEWS:
            raise InputError(_too_few_message(session, cam, views[cam], detections, excluded), session.folder)
    cams = list(session.cameras)
    ref = session.depth_camera or cams[0]

    # 1. intrinsics per camera, the lens model chosen by cross-validation
    intr: dict[str, Any] = {}
    with progress.stage("intrinsics", 0.0):
        for i, cam in enumerate(cams):
            progress(0.3 * i / len(cams), f"intrinsics of {cam} ({len(views[cam])} views)")
            if cam in known:
                k = known[cam]
                intr[cam] = (k.K, k.dist, _known_intrinsics_poses(k, views[cam], board), None)
            else:
                intr[cam] = _calibrate_intrinsics(cam, views[cam], board, sizes[cam])

    # 2. initial extrinsics: cameras placed one by one (most shared poses first) against the
    # board poses already known in the rig frame; for a symmetric board each view's two corner
    # orders are both tried and the one consistent with the rig kept
    symmetric = board.is_symmetric
    # placement starts at the camera whose own views determine its lens best (the reference's may
    # not: e.g. boards all facing it); cameras whose own views leave their focal length undetermined
    # come last, calibrated from the board corners already placed in 3D (not planar any more)
    rel = {c: (0.0 if c in known else getattr(intr[c][3], "focal_rel_std", 0.0)) for c in cams}
    weak_f = {c for c in cams if not rel[c] <= UNDETERMINED_FOCAL}
    anchor = min(cams, key=lambda c: (rel[c], c != ref))
    placed: dict[str, tuple[np.ndarray, np.ndarray]] = {anchor: (np.eye(3), np.zeros(3))}
    flipped: set[tuple[str, str]] = set()
    board_rig: dict[str, tuple[np.ndarray, np.ndarray]] = {p: intr[anchor][2][p] for p in views[anchor]}

    def own(cam, p):
        R, t = intr[cam][2][p]
        return flip_pose(board, R, t) if (p, cam) in flipped else (R, t)

    while len(placed) < len(cams):
        todo = [c for c in cams if c not in placed]
        b = max(todo, key=lambda c: (c not in weak_f, len(set(views[c]) & set(board_rig))))
        shared = sorted(set(views[b]) & set(board_rig))
        if not shared:
            c = todo[0]
            others = sorted({p for o in placed for p in views[o]})
            raise InputError(
                f"camera '{c}' shares no board pose with {', '.join(sorted(placed))}: it saw the board in "
                f"{', '.join(sorted(views[c]))}, the others in {', '.join(others)}. Record poses in which "
                f"'{c}' and another camera see the board at the same time", session.folder)
        if b in weak_f and len(weak_f) < len(cams) and not symmetric:
            K, dist, R_b, t_b = _calibrate_from_3d(b, views[b], shared, board_rig, board, sizes[b], intr[b][3])
            intr[b] = (K, dist, {p: _pnp_pose(views[b][p], board, K, dist) for p in views[b]}, intr[b][3])
            placed[b] = (R_b, t_b)
        else:
            cands = []
            for p in shared:
                R_rb, t_rb = board_rig[p]
                for f in ((0, 1) if symmetric else (0,)):
                    R_bb, t_bb = intr[b][2][p]
                    if f:
                        R_bb, t_bb = flip_pose(board, R_bb, t_bb)
                    R_b_rig = R_bb @ R_rb.T
                    cands.append((p, f, R_b_rig, t_bb - R_b_rig @ t_rb))
            chosen = _consensus(cands)
            for p, (f, _R, _t) in chosen.items():
                if f:
                    flipped.add((p, b))
            placed[b] = _medoid_pose([(R, t) for _f, R, t in chosen.values()])
        Rb, tb = placed[b]
        for p in views[b]:
            if p not in board_rig:
                R_bb, t_bb = own(b, p)
                board_rig[p] = (Rb.T @ R_bb, Rb.T @ (t_bb - tb))
    if anchor != ref:  # express everything in the reference camera's frame
        R_ref, t_ref = placed[ref]
        placed = {c: (R @ R_ref.T, t - R @ R_ref.T @ t_ref) for c, (R, t) in placed.items()}
        placed[ref] = (np.eye(3), np.zeros(3))  # exactly (not -0.0 mm of rounding)
    progress(0.35, "initial extrinsics")

    # board poses in the rig frame: the medoid of what the cameras that saw the pose say. A view
    # disagreeing with it by more than INCONSISTENT_DEG (e.g. a corner order flipped by 180
    # degrees) is left out of the joint estimate and reported, never used silently.
    views = oriented_views(views, flipped)
    all_poses = sorted({p for c in cams for p in views[c]})
    init_board, outliers = {}, {}
    for p in all_poses:
        preds = {}
        for c in [ref] + [c for c in cams if c != ref]:
            if p in views[c]:
                Rc, tc = placed[c]
                Rcb, tcb = own(c, p)
                preds[c] = (Rc.T @ Rcb, Rc.T @ (tcb - tc))
        init_board[p] = _medoid_pose(list(preds.values())) if len(preds) > 2 else next(iter(preds.values()))
        for c, (Rp, _tp) in preds.items():
            ang = _angle_deg(Rp @ init_board[p][0].T)
            if ang > INCONSISTENT_DEG:
                outliers[(p, c)] = ang

    # 3. joint refinement (with the covariance of every camera's parameters)
    obs = [(p, c, *_view_points(views[c][p], board)) for c in cams for p in sorted(views[c]) if (p, c) not in outliers]
    blocks = {}
    for c in cams:
        K0, d0 = intr[c][0], np.asarray(intr[c][1], float)
        if c in known:
            k = known[c]
            names = param_names(len(d0))
            fixed = set(names[: 4 + len(d0)]) - set(k.std)
            prior = {n: (float(_cam_value(K0, d0, n)), s) for n, s in k.std.items() if n in names[: 4 + len(d0)]}
            blocks[c] = CameraBlock(K0, d0, *placed[c], fixed=fixed, prior=prior)
        else:
            blocks[c] = CameraBlock(K0, d0, *placed[c], fixed=set(intr[c][3].model.fixed),
                                    prior=principal_point_prior(sizes[c]))
    with progress.stage("joint refinement", 0.35):
        ba = bundle_adjust(cams, ref, blocks, init_board, obs, progress.sub(0.35, 0.6), covariance=False)
        # again with every camera's residuals weighed by its own corner noise (a 4K camera's
        # detector and a thermal camera's differ): maximum likelihood, and an honest covariance
        noise = {c: max(ba.sigma_cam.get(c, 1.0), 1e-3) for c in cams}
        for c in cams:
            K1, d1, R1, t1 = ba.cams[c]
            blocks[c] = replace(blocks[c], K=K1, dist=d1, R_cam_rig=R1, t_cam_rig=t1)
        ba = bundle_adjust(cams, ref, blocks, ba.boards, obs, progress.sub(0.6, 0.85), noise=noise)
    cam_res, board_res, joint_rms = ba.cams, ba.boards, ba.rms_px

    # 4. per-view errors, weak views, uncertainty
    intrinsics: dict[str, CameraCalibration] = {}
    view_pose_deg: dict[tuple[str, str], float] = {}
    view_board_cam: dict[tuple[str, str], tuple[np.ndarray, np.ndarray]] = {}
    unc: dict[str, CameraUncertainty] = {}
    cameras = []
    for cam in cams:
        K, dist, R, t = cam_res[cam]
        init = {p: (R @ board_res[p][0], R @ board_res[p][1] + t) for p in views[cam]}
        rot_sd: dict[str, float] = {}
        per_view, own_poses, resid, rms = _per_view_errors(
            K, dist, views[cam], board, {p: v for p, v in init.items() if (p, cam) not in outliers}, rot_sd)
        noise = ba.sigma_cam.get(cam, rms / np.sqrt(2.0))
        allr = np.concatenate([np.linalg.norm(r, axis=1) for r in resid.values()])
        weak = []
        med = float(np.median(list(per_view.values())))
        for p, e in per_view.items():
            Rown = own_poses[p][0]
            ang = _angle_deg(Rown @ init[p][0].T)
            view_pose_deg[(p, cam)] = ang
            view_board_cam[(p, cam)] = own_poses[p]
            # a view's own pose is uncertain too (a 160 px thermal image's by ~1 deg): only a
            # disagreement beyond 3 of its standard errors says the view is bad
            own_sd = rot_sd.get(p, 0.0) * noise
            if (p, cam) in outliers or ang > max(WEAK_POSE_DEG, WEAK_POSE_SIGMAS * own_sd):
                weak.append((p, e, f"board pose disagrees with the other cameras by {ang:.1f} deg"
                             + (f" ({ang / own_sd:.1f} x its own pose's standard error)" if own_sd > 0 else "")
                             + (" (corner order flipped? check the polarity)" if ang > 150 else "")
                             + ("; left out of the joint estimate" if (p, cam) in outliers else "")))
            elif e > max(WEAK_FACTOR * med, med + WEAK_MIN_EXCESS_PX):
                weak.append((p, e, f"error {e:.3f} px is {e / med:.1f}x the median {med:.3f} px"))
        weak.sort(key=lambda w: (-("disagrees" in w[2]), -w[1]))
        w, h = sizes[cam]
        used_uv = [views[cam][p].corners.astype(float) for p in views[cam] if (p, cam) not in outliers]
        dists = [float(np.linalg.norm(init[p][1])) for p in views[cam] if (p, cam) not in outliers]
        tb = np.array([board_res[p][1] for p in ba.board_order])
        unc[cam] = projection_uncertainty(cam, K, dist, R, t, ba.cov[cam], ba.names[cam], (w, h),
                                          float(np.median(dists)), used_uv, cam == ref,
                                          (tb, ba.cov_cam_board[cam], ba.cov_board))
        unc[cam].plane_spread_deg = plane_spread_deg(
            [own_poses[p][0] for p in views[cam] if (p, cam) not in outliers and p in own_poses])
        cc = CameraCalibration(cam, session.cameras[cam], w, h, K, dist, rms, float(allr.mean()),
                               dict(sorted(per_view.items())), weak, len(per_view))
        cc.model = intr[cam][3]
        cc.known = known.get(cam)
        intrinsics[cam] = cc
        cameras.append(Camera(cam, session.cameras[cam], w, h, K, dist, R, t))
    rig = Rig(cameras, session.depth_camera, session.depth_scale)
    progress(1.0, "calibration done")
    used = sorted((p, c) for c in cams for p in views[c] if (p, c) not in outliers)
    cal = Calibration(rig, board, intrinsics, board_res, used, joint_rms, ref, view_pose_deg, view_board_cam,
                      excluded_view_errors(intrinsics, session, oriented_views_detections(detections, flipped),
                                           excluded))
    cal.uncertainty = unc
    cal.flipped = flipped
    cal.sigma_px = float(np.sqrt(np.mean([v**2 for v in ba.sigma_cam.values()]))) if ba.sigma_cam else float("nan")
    cal.noise_px = dict(ba.sigma_cam)
    return cal


def _cam_value(K: np.ndarray, dist: np.ndarray, name: str) -> float:
    return {"fx": K[0, 0], "fy": K[1, 1], "cx": K[0, 2], "cy": K[1, 2]}.get(name) if name in ("fx", "fy", "cx", "cy") \
        else float(dist[DIST_NAMES.index(name)])


def oriented_views_detections(detections: dict[tuple[str, str], Detection], flipped) -> dict[tuple[str, str], Detection]:
    """``detections`` with the corner order of ``flipped`` views reversed."""
    if not flipped:
        return detections
    return {k: (flipped_detection(d) if k in flipped and d.corners is not None else d) for k, d in detections.items()}


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
