"""What the calibration's own data say about how well it is determined.

From the joint bundle adjustment's covariance (:mod:`.bundle`) of each camera's parameters:

* **standard errors** of every intrinsic (fx, fy, cx, cy, distortion) and of every camera's pose
  relative to the reference camera (rotation in degrees, translation in mm);
* **projection uncertainty** (mrcal-style): a grid of image points is back-projected with the
  calibrated model to the camera's *working distance* (the median distance of its board views),
  and the parameters' covariance is propagated to where those 3D points project
  (``Sigma_q = J Sigma_theta J^T``, 2 x 2 per point). The figure per point is the standard
  deviation in the direction the projection is least certain (sqrt of the larger eigenvalue, as
  mrcal reports it), in pixels. ``intrinsics``: the point
  fixed in the camera's own frame (lens model only); ``rig``: the point fixed in the rig
  (reference camera) frame, so the pose's uncertainty counts too (equal for the reference).
  With Gaussian corner noise of the estimated size the true error lies within 2 x this figure in
  87 % (round error ellipse) to 95 % (elongated) of cases; on simulated sessions with known truth
  (tests/test_calibration_uncertainty.py) it does in 90-98 % of image points.

It does *not* measure a wrong model (a lens the model cannot describe; the cross-validated lens
model choice guards against that), a wrong board size, corners that are biased (blur, a bent
board), cameras that moved between poses, or views that are not simultaneous. A low reprojection
error says nothing about whether the data determine the model; this does.

**Limits** (``plantreg calibrate`` refuses beyond them unless ``--accept-uncertain``): board
views whose planes all lie within ``MIN_PLANE_SPREAD_DEG`` of one another (Zhang's degenerate
case); a camera's projection uncertainty as mrcal figures it (the point fixed among the board
poses), the worst over the working band ``LIMIT_BAND`` (0.8-1.25x the boards' distance), its median
over the image (``MAX_PROJECTION_SIGMA_MEDIAN``: px, or a fraction of the image diagonal for large
images) and its worst where the camera saw board corners (``MAX_PROJECTION_SIGMA_COVERED``); a camera's pose relative to the reference
by its projection of points fixed in the reference camera's frame (the ``rig`` figure, median,
``MAX_PROJECTION_SIGMA_MEDIAN``: a rotation traded against the camera's principal point moves
nothing there) and its translation (``MAX_TRANSLATION_SIGMA_MM``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np

from .bundle import _skew, project_jac

#: median over the image of a camera's projection uncertainty: at most this many px, or this
#: fraction of the image diagonal if more (1 px up to 640 x 480, 2.9 px on 1280 x 720, 8.8 px on 4K)
MAX_PROJECTION_SIGMA_MEDIAN = (1.0, 0.002)
#: worst projection uncertainty where the camera saw board corners (grid cells with corners), px
#: or fraction of the diagonal; outside them the figure is reported, not limited (the corners of
#: an image nobody put a board in are extrapolation, shown on the heat map)
MAX_PROJECTION_SIGMA_COVERED = (2.0, 0.004)
MAX_TRANSLATION_SIGMA_MM = 10.0
#: board planes all turned within this many degrees of one another (the largest angle between two
#: views' board normals, in the camera's frame) are Zhang's degenerate case: parallel planes leave
#: the focal length to the lens distortion and the noise, and the covariance (linearised at a
#: solution that fits) does not show how little holds it
MIN_PLANE_SPREAD_DEG = 10.0
#: grid cells along the image's longer side
GRID_CELLS = 24
#: multiples of the working distance at which mrcal's figure is also reported (1000: far away)
BOARDS_DISTANCE_FACTORS = (0.5, 2.0, 1000.0)
#: multiples of the working distance over which the limits judge a camera (the worst of the three
#: at each image point): a canopy's leaves lie nearer and farther than the board did, and a focal
#: length that only the boards' own distance pins down shows there (a fronto-parallel session:
#: a focal length off by e moves the points at 0.8x by e/4 of their distance from the centre)
LIMIT_BAND = (0.8, 1.0, 1.25)


@dataclass
class CameraUncertainty:
    """One camera's uncertainty. ``std`` parameter name -> standard error (px for fx..cy,
    unitless for distortion; rotation in deg as "rotation_deg" and translation in mm as
    "translation_mm" for non-reference cameras); ``grid_u``/``grid_v`` (W,) and (H,) pixel
    centres of the grid; ``sigma_intrinsics``/``sigma_rig`` (H, W) px; ``corners`` (H, W)
    number of used board views covering each cell; ``distance_m`` the working distance."""

    name: str
    std: dict[str, float]
    distance_m: float
    grid_u: np.ndarray
    grid_v: np.ndarray
    sigma_intrinsics: np.ndarray
    sigma_rig: np.ndarray
    corners: np.ndarray
    worst_param: str = ""
    rotation_deg: float | None = None
    translation_mm: float | None = None
    add_views: list[str] = field(default_factory=list)
    width: int = 0
    height: int = 0
    #: (H, W) px: mrcal's figure, the point fixed among the board poses (see
    #: :func:`sigma_among_boards`); reported, not limited
    sigma_boards: np.ndarray | None = None
    #: multiple of the working distance -> median of ``sigma_boards`` there (px)
    boards_by_distance: dict[float, float] = field(default_factory=dict)
    #: multiple of the working distance (:data:`LIMIT_BAND`) -> (H, W) px, mrcal's figure there
    sigma_boards_at: dict[float, np.ndarray] = field(default_factory=dict)
    #: (H, W) px: the figure the limits judge: the worst of ``sigma_boards_at`` (mrcal's figure
    #: over the working band) or, without board poses, ``sigma_intrinsics``
    sigma_judged: np.ndarray | None = None
    #: the largest angle between two used views' board planes, deg (:func:`plane_spread_deg`)
    plane_spread_deg: float | None = None

    @property
    def judged(self) -> np.ndarray:
        """(H, W) px: the figure the limits apply to (see ``sigma_judged``)."""
        return self.sigma_judged if self.sigma_judged is not None else self.sigma_intrinsics

    @property
    def band_m(self) -> tuple[float, float]:
        """The working band (nearest, farthest) in metres the limits judge."""
        return LIMIT_BAND[0] * self.distance_m, LIMIT_BAND[-1] * self.distance_m

    def summary(self, which: str = "judged") -> tuple[float, float]:
        """(median, worst) over the image, px, of ``which``: "judged" (what the limits apply to),
        "intrinsics" (the lens model alone) or "rig"."""
        s = {"judged": self.judged, "intrinsics": self.sigma_intrinsics, "rig": self.sigma_rig}[which]
        return float(np.median(s)), float(np.max(s))

    @property
    def covered_worst(self) -> float:
        """Worst judged projection uncertainty (px) over the grid cells some board view covered."""
        m = self.corners > 0
        return float(np.max(self.judged[m])) if m.any() else float("inf")

    @property
    def needs_views(self) -> bool:
        """Whether a projection limit is exceeded (``add_views`` then says where to add views;
        else it names only where the uncertainty is highest, within the limits)."""
        lim_med, lim_seen = limits_px(self)
        return bool(self.summary()[0] > lim_med or self.covered_worst > lim_seen)

    @property
    def diagonal(self) -> float:
        return float(np.hypot(self.width, self.height))

    def to_dict(self) -> dict[str, Any]:
        mj, wj = self.summary("judged")
        mi, wi = self.summary("intrinsics")
        mr, wr = self.summary("rig")
        return {"std": self.std, "working_distance_m": self.distance_m,
                "working_band_m": list(self.band_m),
                "projection_sigma_px": {"median": mj, "worst": wj, "worst_where_seen": self.covered_worst,
                                        "lens_alone_median": mi, "lens_alone_worst": wi,
                                        "rig_median": mr, "rig_worst": wr,
                                        "among_boards_median": float(np.median(self.sigma_boards))
                                        if self.sigma_boards is not None else None,
                                        "among_boards_median_by_distance": {
                                            f"{f:g}x": v for f, v in self.boards_by_distance.items()}},
                "least_determined": self.worst_param,
                "board_plane_spread_deg": self.plane_spread_deg,
                "rotation_sigma_deg": self.rotation_deg, "translation_sigma_mm": self.translation_mm,
                "add_views_here": self.add_views if self.needs_views else [],
                "least_certain_regions": self.add_views,
                "grid": {"u": self.grid_u.tolist(), "v": self.grid_v.tolist(),
                         "sigma_px": np.round(self.judged, 4).tolist(),
                         "lens_alone_sigma_px": np.round(self.sigma_intrinsics, 4).tolist(),
                         "rig_sigma_px": np.round(self.sigma_rig, 4).tolist(),
                         "corners": self.corners.astype(int).tolist()}}


def _grid(width: int, height: int, cells: int = GRID_CELLS) -> tuple[np.ndarray, np.ndarray]:
    n = max(width, height)
    nu = max(4, int(round(cells * width / n)))
    nv = max(4, int(round(cells * height / n)))
    u = (np.arange(nu) + 0.5) * width / nu - 0.5
    v = (np.arange(nv) + 0.5) * height / nv - 0.5
    return u, v


def _region(u: float, v: float, w: int, h: int) -> str:
    col = ["left", "centre", "right"][min(2, int(3 * (u + 0.5) / w))]
    row = ["top", "middle", "bottom"][min(2, int(3 * (v + 0.5) / h))]
    return "centre" if (row, col) == ("middle", "centre") else f"{row} {col}" if col != "centre" else f"{row} centre"


def _worst_direction(S: np.ndarray) -> np.ndarray:
    """sqrt of the larger eigenvalue of each 2 x 2 covariance (n, 2, 2): the standard deviation
    in the direction the projection is least certain (mrcal's convention)."""
    a, b, d = S[:, 0, 0], S[:, 0, 1], S[:, 1, 1]
    return np.sqrt(np.maximum((a + d) / 2 + np.sqrt(((a - d) / 2) ** 2 + b * b), 0.0))


def sigma_among_boards(J_cam: np.ndarray, dq_dZ: np.ndarray, X_rig: np.ndarray, R_cam_rig: np.ndarray,
                       cov: np.ndarray, t_rig_board: np.ndarray, cov_cam_board: np.ndarray,
                       cov_board: np.ndarray) -> np.ndarray:
    """(n,) px: the projection uncertainty of points ``X_rig`` (n, 3) fixed among the board poses
    (mrcal's "mean frames": the point moves with the mean of the boards' perturbations, so a shift of
    cx that a turn of every board relative to the camera undoes, or a focal length that a change of
    every board's distance undoes, does not count). ``J_cam`` (n, 2, n_c) d q / d camera
    parameters (point fixed in the rig), ``dq_dZ`` (n, 2, 3), ``t_rig_board`` (P, 3),
    ``cov_cam_board`` (n_c, 6 P), ``cov_board`` (6 P, 6 P)."""
    P = len(t_rig_board)
    n = len(X_rig)
    # board i perturbed (R <- exp(w) R, t <- t + dt) moves X by w x (X - t_i) + dt; the mean over i
    dX = np.zeros((n, 3, 6 * P))
    for i in range(P):
        dX[:, :, 6 * i : 6 * i + 3] = -_skew(X_rig - t_rig_board[i]) / P
        dX[:, :, 6 * i + 3 : 6 * i + 6] = np.eye(3) / P
    Jb = np.einsum("nij,njk->nik", dq_dZ @ R_cam_rig, dX)
    S = (np.einsum("nij,jk,nlk->nil", J_cam, cov, J_cam) + np.einsum("nij,jk,nlk->nil", Jb, cov_board, Jb)
         + 2 * np.einsum("nij,jk,nlk->nil", J_cam, cov_cam_board, Jb))
    S = 0.5 * (S + S.transpose(0, 2, 1))
    return _worst_direction(S)


def projection_uncertainty(name: str, K: np.ndarray, dist: np.ndarray, R_cam_rig: np.ndarray,
                           t_cam_rig: np.ndarray, cov: np.ndarray, param_names: list[str], size: tuple[int, int],
                           distance_m: float, views_uv: list[np.ndarray], is_reference: bool,
                           boards: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None) -> CameraUncertainty:
    """The uncertainty of one camera (see the module docstring). ``cov`` (n, n) of the
    parameters ``param_names`` (fx, fy, cx, cy, dist..., rx, ry, rz, tx, ty, tz);
    ``views_uv`` [(N, 2)] the used corners of each view (for the coverage map: the number of
    views whose board, the corners' convex hull, covers each grid cell)."""
    w, h = size
    nd = len(dist)
    gu, gv = _grid(w, h)
    uu, vv = np.meshgrid(gu, gv)
    uv = np.c_[uu.ravel(), vv.ravel()].astype(np.float64)
    xy = cv2.undistortPoints(uv.reshape(-1, 1, 2), K, dist, None, None, np.eye(3),
                             criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-10)).reshape(-1, 2)
    X_cam = np.c_[xy, np.ones(len(xy))] * distance_m
    # camera frame: d q / d (f, c, dist)
    _q, dq_dZ, Ji = project_jac(X_cam, K, dist)
    ci = cov[: 4 + nd, : 4 + nd]
    sig_i = _worst_direction(np.einsum("nij,jk,nlk->nil", Ji, ci, Ji)).reshape(len(gv), len(gu))
    # rig frame: the same points fixed in the rig, so the camera's pose (R <- exp(w) R, t) moves
    # them: d Z / d w = -[Z - t]x, d Z / d t = I
    Jr = np.concatenate([Ji, -dq_dZ @ _skew(X_cam - t_cam_rig), dq_dZ], axis=2)
    sig_r = _worst_direction(np.einsum("nij,jk,nlk->nil", Jr, cov, Jr)).reshape(len(gv), len(gu))

    def among_boards(f: float) -> np.ndarray:
        """(H, W) px: mrcal's figure for the grid's points at ``f`` x the working distance."""
        Xf = X_cam * f
        _q, dq_dZf, Jif = project_jac(Xf, K, dist)
        Jrf = np.concatenate([Jif, -dq_dZf @ _skew(Xf - t_cam_rig), dq_dZf], axis=2)
        return sigma_among_boards(Jrf, dq_dZf, (Xf - t_cam_rig) @ R_cam_rig, R_cam_rig, cov,
                                  *boards).reshape(len(gv), len(gu))

    sig_b = None
    boards_at = {f: among_boards(f) for f in LIMIT_BAND} if boards is not None else {}
    if boards_at:
        sig_b = boards_at[1.0]
    judged = np.max(np.stack(list(boards_at.values())), axis=0) if boards_at else sig_i
    # standard errors
    var = np.diag(cov)
    std: dict[str, float] = {}
    for j, n in enumerate(param_names[: 4 + nd]):
        std[n] = float(np.sqrt(max(var[j], 0.0)))
    rot = trans = None
    if not is_reference:
        rot = float(np.degrees(np.sqrt(max(np.trace(cov[4 + nd : 7 + nd, 4 + nd : 7 + nd]), 0.0))))
        trans = float(1000.0 * np.sqrt(max(np.trace(cov[7 + nd : 10 + nd, 7 + nd : 10 + nd]), 0.0)))
        std["rotation_deg"], std["translation_mm"] = rot, trans
    # the parameter that contributes most (lens model alone) to the worst judged point's variance
    k = int(np.argmax(judged.ravel()))
    contrib = [float(Ji[k, :, j] @ Ji[k, :, j]) * var[j] for j in range(4 + nd)]
    worst = param_names[int(np.argmax(contrib))] if max(contrib) > 0 else ""
    # coverage: views whose board covers each grid cell's centre
    cnt = np.zeros((len(gv), len(gu)))
    scale = np.array([len(gu) / w, len(gv) / h])
    for c in views_uv:
        if len(c) < 3:
            continue
        hull = cv2.convexHull(np.asarray(c, np.float32).reshape(-1, 1, 2)).reshape(-1, 2)
        m = np.zeros(cnt.shape, np.uint8)  # the hull rasterised at the grid's resolution
        cv2.fillConvexPoly(m, np.round(((hull + 0.5) * scale - 0.5) * 16).astype(np.int32), 1, cv2.LINE_8, 4)
        cnt += m
    # "add views here": regions holding the highest uncertainty, fewest corners first
    add = []
    order = np.argsort(-judged.ravel())
    for k in order[: max(3, len(order) // 10)]:
        r = _region(uv[k, 0], uv[k, 1], w, h)
        if r not in add:
            add.append(r)
        if len(add) >= 3:
            break
    out = CameraUncertainty(name, std, float(distance_m), gu, gv, sig_i, sig_r, cnt, worst, rot, trans, add, w, h)
    out.sigma_boards = sig_b
    out.sigma_boards_at = boards_at
    out.sigma_judged = judged if boards_at else None
    if boards is not None:
        out.boards_by_distance = {f: float(np.median(among_boards(f))) for f in BOARDS_DISTANCE_FACTORS}
    return out


def plane_spread_deg(R_cam_board: list[np.ndarray]) -> float:
    """The largest angle (deg) between two views' board planes (normals: the third column of
    each (3, 3) ``R_cam_board``; a plane's two sides are the same plane)."""
    if len(R_cam_board) < 2:
        return 0.0
    n = np.array([R[:, 2] for R in R_cam_board])
    c = np.abs(n @ n.T)
    return float(np.degrees(np.arccos(np.clip(c.min(), -1.0, 1.0))))


def limits_px(u: CameraUncertainty) -> tuple[float, float]:
    """The (median, where-seen) projection uncertainty limits of a camera in its pixels."""
    (a, fa), (b, fb) = MAX_PROJECTION_SIGMA_MEDIAN, MAX_PROJECTION_SIGMA_COVERED
    return max(a, fa * u.diagonal), max(b, fb * u.diagonal)


def uncertainty_problems(unc: dict[str, CameraUncertainty], max_mm: float | None = None) -> list[str]:
    """One sentence per camera whose uncertainty exceeds a limit, naming the parameter."""
    max_mm = MAX_TRANSLATION_SIGMA_MM if max_mm is None else max_mm
    out = []
    for name, u in unc.items():
        med, _worst = u.summary()
        seen = u.covered_worst
        lim_med, lim_seen = limits_px(u)
        p = u.worst_param
        where = f"least determined: {p} +- {u.std.get(p, float('nan')):.3g}" if p else "the model is undetermined"
        lo, hi = u.band_m
        at = f"{lo:.2f}-{hi:.2f} m" if u.sigma_judged is not None else f"{u.distance_m:.2f} m"
        focal = [k for k in ("fx", "fy") if u.std.get(k, 0.0) > 0]
        if focal and u.plane_spread_deg is not None and u.plane_spread_deg < MIN_PLANE_SPREAD_DEG:
            out.append(f"camera '{name}': its board views are all turned within {u.plane_spread_deg:.1f} deg of one "
                       f"another (at least {MIN_PLANE_SPREAD_DEG:g} deg apart needed: parallel boards leave the focal length "
                       f"to the lens distortion); least determined: {focal[0]} +- {u.std[focal[0]]:.3g}; add board "
                       "views tilted 20-45 deg towards different sides")
        elif not np.isfinite(med) or med > lim_med:
            out.append(f"camera '{name}': projection uncertainty {med:.2f} px (median over the image, at "
                       f"{at}) exceeds the limit of {lim_med:.2f} px; {where}; add board views in the {', '.join(u.add_views)} of the image, "
                       "tilted, at several distances")
        elif not np.isfinite(seen) or seen > lim_seen:
            out.append(f"camera '{name}': projection uncertainty up to {seen:.2f} px where it saw the board (at "
                       f"{at}) exceeds the limit of {lim_seen:.2f} px; {where}; add board views in the {', '.join(u.add_views)} of the image, "
                       "tilted, at several distances")
        if u.rotation_deg is not None:
            # the pose judged by what it does where the camera sees: a rotation traded against the
            # camera's own principal point (a thermal camera's +- 1 deg and +- 2 px) moves nothing
            rig_med = u.summary("rig")[0]
            if not np.isfinite(rig_med) or rig_med > lim_med:
                out.append(f"camera '{name}': its pose relative to the reference (rotation +- {u.rotation_deg:.3f} deg, "
                           f"translation +- {u.translation_mm:.2f} mm) leaves where it sees points fixed in the "
                           f"reference camera's frame uncertain by {rig_med:.2f} px (median over the image, at "
                           f"{u.distance_m:.2f} m), beyond the limit of {lim_med:.2f} px; record more poses seen by it "
                           "and the reference camera together")
        if u.translation_mm is not None and (not np.isfinite(u.translation_mm) or u.translation_mm > max_mm):
            out.append(f"camera '{name}': translation relative to the reference uncertain by +- {u.translation_mm:.2f} mm "
                       f"(limit {max_mm:g} mm); record more poses seen by it and the reference camera together, "
                       "nearer and tilted")
    return out
