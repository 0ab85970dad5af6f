"""The joint bundle adjustment of a rig and its covariance.

One Levenberg-Marquardt fit of every camera's intrinsics and pose (``R_cam_rig``, ``t_cam_rig``;
the reference camera's pose is the identity) and every board pose (``R_rig_board``,
``t_rig_board``), minimising the reprojection error of every used corner. Jacobians come from
``cv2.projectPoints`` chained through ``cv2.composeRT``. The normal equations are kept in their
sparse block form -- camera parameters (few) x board poses (many, each 6 x 6 block-diagonal) --
and solved by the Schur complement over the board poses, which is also how the covariance of the
camera parameters is obtained (the board poses are nuisance parameters): ``Cov = s^2 S^-1`` with
``S = A - B C^-1 B^T`` and ``s^2`` the residual variance (sum of squared residuals / degrees of
freedom). A robust weight (soft-L1, quadratic below ``f_scale`` px) keeps one misdetected view
from dragging the rig; the covariance uses the same weights.

Parameter vector of one camera (``CAM_PARAMS`` then the distortion coefficients in OpenCV's
order): fx, fy, cx, cy, k1, k2, p1, p2, k3[, k4, k5, k6], rx, ry, rz, tx, ty, tz (Rodrigues
rotation and translation of ``X_cam = R_cam_rig X_rig + t_cam_rig``, metres).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from ..progress import Reporter, ensure_reporter

DIST_NAMES = ("k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6")
POSE_NAMES = ("rx", "ry", "rz", "tx", "ty", "tz")


def param_names(nd: int) -> list[str]:
    """Names of one camera's parameters (``nd`` distortion coefficients, 5 or 8)."""
    return ["fx", "fy", "cx", "cy", *DIST_NAMES[:nd], *POSE_NAMES]


@dataclass
class CameraBlock:
    """One camera's start values and what is held fixed. ``K`` (3, 3), ``dist`` (nd,),
    ``R_cam_rig`` (3, 3), ``t_cam_rig`` (3,); ``fixed`` names of parameters held at their
    start value (e.g. "cx", "k3"); ``prior`` name -> (value, standard error): a soft
    constraint (known intrinsics with their uncertainty)."""

    K: np.ndarray
    dist: np.ndarray
    R_cam_rig: np.ndarray
    t_cam_rig: np.ndarray
    fixed: set[str] = field(default_factory=set)
    prior: dict[str, tuple[float, float]] = field(default_factory=dict)

    def vector(self) -> np.ndarray:
        K = self.K
        return np.concatenate([[K[0, 0], K[1, 1], K[0, 2], K[1, 2]], self.dist,
                               cv2.Rodrigues(np.asarray(self.R_cam_rig, float))[0].ravel(), self.t_cam_rig])


def _skew(v: np.ndarray) -> np.ndarray:
    """(n, 3) -> (n, 3, 3) cross-product matrices."""
    z = np.zeros(len(v))
    return np.stack([np.stack([z, -v[:, 2], v[:, 1]], -1), np.stack([v[:, 2], z, -v[:, 0]], -1),
                     np.stack([-v[:, 1], v[:, 0], z], -1)], 1)


def project_jac(Z: np.ndarray, K: np.ndarray, dist: np.ndarray, jacobians: bool = True):
    """OpenCV's camera model (5 or 8 coefficients) for camera-frame points ``Z`` (n, 3):
    pixels (n, 2), d pixel / d Z (n, 2, 3) and d pixel / d (fx, fy, cx, cy, dist...) (n, 2, 4 + nd)."""
    nd = len(dist)
    k = np.zeros(8)
    k[:nd] = dist
    k1, k2, p1, p2, k3, k4, k5, k6 = k
    iz = 1.0 / Z[:, 2]
    x, y = Z[:, 0] * iz, Z[:, 1] * iz
    r2 = x * x + y * y
    r4, r6 = r2 * r2, r2 * r2 * r2
    num = 1 + k1 * r2 + k2 * r4 + k3 * r6
    den = 1 + k4 * r2 + k5 * r4 + k6 * r6
    rad = num / den
    xd = x * rad + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    yd = y * rad + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    q = np.stack([fx * xd + cx, fy * yd + cy], axis=1)
    if not jacobians:
        return q, None, None
    drad_dr2 = (k1 + 2 * k2 * r2 + 3 * k3 * r4) / den - num * (k4 + 2 * k5 * r2 + 3 * k6 * r4) / den**2
    dxd_dx = rad + x * drad_dr2 * 2 * x + 2 * p1 * y + p2 * 6 * x
    dxd_dy = x * drad_dr2 * 2 * y + 2 * p1 * x + p2 * 2 * y
    dyd_dx = y * drad_dr2 * 2 * x + p1 * 2 * x + 2 * p2 * y
    dyd_dy = rad + y * drad_dr2 * 2 * y + p1 * 6 * y + 2 * p2 * x
    n = len(Z)
    dq_dxy = np.empty((n, 2, 2))
    dq_dxy[:, 0, 0], dq_dxy[:, 0, 1] = fx * dxd_dx, fx * dxd_dy
    dq_dxy[:, 1, 0], dq_dxy[:, 1, 1] = fy * dyd_dx, fy * dyd_dy
    dxy_dZ = np.zeros((n, 2, 3))
    dxy_dZ[:, 0, 0], dxy_dZ[:, 0, 2] = iz, -x * iz
    dxy_dZ[:, 1, 1], dxy_dZ[:, 1, 2] = iz, -y * iz
    dq_dZ = dq_dxy @ dxy_dZ
    Ji = np.zeros((n, 2, 4 + nd))
    Ji[:, 0, 0], Ji[:, 1, 1], Ji[:, 0, 2], Ji[:, 1, 3] = xd, yd, 1.0, 1.0
    # distortion: radial terms through rad, tangential directly
    drad = [r2 / den, r4 / den, None, None, r6 / den, -num * r2 / den**2, -num * r4 / den**2, -num * r6 / den**2]
    for j in range(nd):
        if j == 2:
            Ji[:, 0, 4 + j], Ji[:, 1, 4 + j] = fx * 2 * x * y, fy * (r2 + 2 * y * y)
        elif j == 3:
            Ji[:, 0, 4 + j], Ji[:, 1, 4 + j] = fx * (r2 + 2 * x * x), fy * 2 * x * y
        else:
            Ji[:, 0, 4 + j], Ji[:, 1, 4 + j] = fx * x * drad[j], fy * y * drad[j]
    return q, dq_dZ, Ji


def _obs_sums(X: np.ndarray, Y: np.ndarray, starts: np.ndarray, same: int) -> np.ndarray:
    """Per observation the sum over its corners of ``X_n^T Y_n``: ``X`` (n, 2, a), ``Y`` (n, 2, b)
    with each observation's corners consecutive from ``starts`` -> (n_obs, a, b). ``same``: the
    corners of every observation when all have as many (one batched product), else 0."""
    if same:
        return np.matmul(X.reshape(-1, 2 * same, X.shape[2]).transpose(0, 2, 1), Y.reshape(-1, 2 * same, Y.shape[2]))
    return np.add.reduceat(np.matmul(X.transpose(0, 2, 1), Y), starts, axis=0)


def _exp(w: np.ndarray) -> np.ndarray:
    return cv2.Rodrigues(np.asarray(w, float).reshape(3, 1))[0]


@dataclass
class BundleResult:
    """``cams`` name -> (K, dist, R_cam_rig, t_cam_rig); ``boards`` pose -> (R_rig_board,
    t_rig_board); ``rms_px`` RMS corner distance; ``sigma_px`` the residual standard deviation
    per coordinate (weighted, per degree of freedom; in units of ``noise`` when given); ``cov`` name -> covariance (n, n) of the
    camera's parameters (``names[name]``; zero rows/columns for fixed ones); ``cross`` (a, b)
    -> cross-covariance of two cameras' parameters; ``residuals`` (pose, cam) -> (N, 2)."""

    cams: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]
    boards: dict[str, tuple[np.ndarray, np.ndarray]]
    rms_px: float
    sigma_px: float
    names: dict[str, list[str]]
    cov: dict[str, np.ndarray]
    cross: dict[tuple[str, str], np.ndarray]
    residuals: dict[tuple[str, str], np.ndarray]
    n_iterations: int = 0
    dof: int = 0
    #: camera -> RMS residual per coordinate (px)
    sigma_cam: dict[str, float] = field(default_factory=dict)
    #: the board poses' side of the covariance, in the order of ``board_order``: camera ->
    #: cross-covariance (n_c, 6 P) of its parameters with the board poses (rx, ry, rz, tx, ty, tz
    #: each), and (6 P, 6 P) of the board poses (what a point fixed among the boards needs)
    board_order: list[str] = field(default_factory=list)
    cov_cam_board: dict[str, np.ndarray] = field(default_factory=dict)
    cov_board: np.ndarray | None = None


def bundle_adjust(cams: list[str], ref: str, blocks: dict[str, CameraBlock],
                  init_board: dict[str, tuple[np.ndarray, np.ndarray]],
                  obs: list[tuple[str, str, np.ndarray, np.ndarray]], progress: Reporter | None = None,
                  f_scale: float | None = None, max_iter: int = 50, noise_px: float | None = None,
                  covariance: bool = True, tol: float = 1e-10,
                  noise: dict[str, float] | None = None, gauss_newton: bool = False) -> BundleResult:
    """Fit all cameras and board poses to ``obs`` [(pose, cam, obj (N, 3), img (N, 2))].

    ``init_board`` pose -> (R_rig_board, t_rig_board). Rotations are updated multiplicatively
    (``R <- exp(w) R``), so a pose's rotation parameters (rx, ry, rz) are a small rotation in
    radians and their covariance is the rotation's. ``f_scale`` (px): the soft-L1 loss is
    quadratic below it (default: 1 px or 2.5 x the median start residual, whichever is larger,
    so that noisy cameras' ordinary corners count fully). ``noise_px``: the corner noise assumed
    to weigh priors against corners (default: the start RMS). ``noise`` camera -> corner noise
    (px per coordinate): each camera's residuals are weighed by it (maximum likelihood when the
    cameras' detectors differ, e.g. a 4K camera and a thermal one); then ``f_scale`` is in units
    of that noise (default 3) and the covariance's residual variance is of the weighed residuals.
    ``gauss_newton``: take ``max_iter`` undamped steps without checking the cost (a refit from a
    nearby solution, as in cross-validation: half the work)."""
    progress = ensure_reporter(progress)
    nd = {c: len(blocks[c].dist) for c in cams}
    names = {c: param_names(nd[c]) for c in cams}
    npar = {c: len(names[c]) for c in cams}
    coff, o = {}, 0
    for c in cams:
        coff[c] = o
        o += npar[c]
    nc = o
    poses = sorted(init_board)
    pidx = {p: i for i, p in enumerate(poses)}
    npose = len(poses)
    intr = {c: blocks[c].vector()[: 4 + nd[c]].astype(float) for c in cams}
    Rc = {c: np.asarray(blocks[c].R_cam_rig, float).copy() for c in cams}
    tc = {c: np.asarray(blocks[c].t_cam_rig, float).copy() for c in cams}
    Rb = np.stack([np.asarray(init_board[p][0], float) for p in poses]) if poses else np.zeros((0, 3, 3))
    tb = np.stack([np.asarray(init_board[p][1], float) for p in poses]) if poses else np.zeros((0, 3))
    free = np.ones(nc, bool)
    for c in cams:
        fixed = set(blocks[c].fixed) | (set(POSE_NAMES) if c == ref else set())
        for j, n in enumerate(names[c]):
            if n in fixed:
                free[coff[c] + j] = False
    prior_idx, prior_val, prior_sig = [], [], []
    for c in cams:
        for n, (v, sg) in blocks[c].prior.items():
            j = coff[c] + names[c].index(n)
            if free[j] and sg > 0 and names[c].index(n) < 4 + nd[c]:
                prior_idx.append(j)
                prior_val.append(v)
                prior_sig.append(sg)
    prior_idx = np.array(prior_idx, int)
    prior_val = np.array(prior_val, float)
    prior_sig = np.array(prior_sig, float)

    # every corner of every observation, grouped by camera, then by observation
    per_cam = {}
    same_len: dict[str, int] = {}  # camera -> the corners of each of its views, when all have as many
    for c in cams:
        mine = [(k, ob) for k, ob in enumerate(obs) if ob[1] == c]
        if not mine:
            per_cam[c] = None
            continue
        obj = np.concatenate([np.asarray(ob[2], float) for _k, ob in mine])
        img = np.concatenate([np.asarray(ob[3], float).reshape(-1, 2) for _k, ob in mine])
        lens = np.array([len(ob[2]) for _k, ob in mine])
        starts = np.r_[0, np.cumsum(lens)[:-1]]
        bidx = np.array([pidx[ob[0]] for _k, ob in mine])
        per_cam[c] = (obj, img, starts, bidx, np.repeat(bidx, lens), [k for k, _ob in mine])
        same_len[c] = int(lens[0]) if np.all(lens == lens[0]) else 0
    n_pts = sum(len(v[0]) for v in per_cam.values() if v is not None)

    def evaluate(intr, Rc, tc, Rb, tb, want_normal: bool, fs: float):
        res = {}
        A = np.zeros((nc, nc)) if want_normal else None
        B = np.zeros((nc, 6 * npose)) if want_normal else None
        C = np.zeros((npose, 6, 6)) if want_normal else None
        ga = np.zeros(nc)
        gb = np.zeros((npose, 6))
        for c in cams:
            if per_cam[c] is None:
                continue
            obj, img, starts, bidx, pb, _ks = per_cam[c]
            same = same_len[c]
            Xb = np.einsum("nij,nj->ni", Rb[pb], obj)
            Y = Xb + tb[pb]
            RY = Y @ Rc[c].T
            Z = RY + tc[c]
            n_d = nd[c]
            K = np.array([[intr[c][0], 0, intr[c][2]], [0, intr[c][1], intr[c][3]], [0, 0, 1.0]])
            q, dq_dZ, Ji = project_jac(Z, K, intr[c][4:], want_normal)
            r = (q - img) / scale[c]
            res[c] = r
            if not want_normal:
                continue
            dq_dZ = dq_dZ / scale[c]
            Ji = Ji / scale[c]
            w = 1.0 / np.sqrt(1.0 + np.sum(r**2, axis=1) / fs**2)
            # a^T (-[v]x) = (v x a)^T: the rotation columns without building skew matrices
            Jc = np.concatenate([Ji, np.cross(RY[:, None, :], dq_dZ), dq_dZ], axis=2)  # (n, 2, pc)
            dq_dY = dq_dZ @ Rc[c]
            Jb = np.concatenate([np.cross(Xb[:, None, :], dq_dY), dq_dY], axis=2)  # (n, 2, 6)
            Jcw = Jc * w[:, None, None]
            Jbw = Jb * w[:, None, None]
            sl = slice(coff[c], coff[c] + npar[c])
            pc = Jc.shape[2]
            Jc2, Jcw2 = Jc.reshape(-1, pc), Jcw.reshape(-1, pc)
            A[sl, sl] += Jcw2.T @ Jc2
            ga[sl] += Jcw2.T @ r.ravel()
            cb = _obs_sums(Jcw, Jb, starts, same)  # (n_obs, pc, 6)
            cc = _obs_sums(Jbw, Jb, starts, same)
            gg = _obs_sums(Jbw, r[:, :, None], starts, same)[:, :, 0]
            for m, b in enumerate(bidx):
                B[sl, 6 * b : 6 * b + 6] += cb[m]
            np.add.at(C, bidx, cc)
            np.add.at(gb, bidx, gg)
        return res, A, B, C, ga, gb.ravel()

    def prior_terms(intr):
        x = np.zeros(nc)
        for c in cams:
            x[coff[c] : coff[c] + 4 + nd[c]] = intr[c]
        return x

    scale = {c: float(noise[c]) if noise and noise.get(c) else 1.0 for c in cams}
    res0 = evaluate(intr, Rc, tc, Rb, tb, False, 1.0)[0]
    allr0 = np.concatenate(list(res0.values())) if res0 else np.zeros((0, 2))
    d0 = np.linalg.norm(allr0, axis=1)
    if noise:
        fs = 3.0 if f_scale is None else float(f_scale)
        pscale = 1.0
    else:
        fs = float(f_scale) if f_scale is not None else max(1.0, 2.5 * float(np.median(d0)) if len(d0) else 1.0)
        pscale = max(float(noise_px) if noise_px is not None else float(np.sqrt(np.mean(d0**2))) if len(d0) else 1.0,
                     1e-3)
    wp = (pscale / prior_sig) ** 2 if len(prior_idx) else np.zeros(0)

    def total_cost(res, intr):
        f = 0.0
        for r in res.values():
            z = np.sum(r**2, axis=1) / fs**2
            f += float(np.sum(2.0 * (np.sqrt(1.0 + z) - 1.0))) * fs**2
        if len(prior_idx):
            f += float(np.sum(wp * (prior_terms(intr)[prior_idx] - prior_val) ** 2))
        return f

    def add_prior(A, ga, intr):
        if len(prior_idx):
            A[prior_idx, prior_idx] += wp
            ga[prior_idx] += wp * (prior_terms(intr)[prior_idx] - prior_val)

    def solve(A, B, C, ga, gb, lam):
        """LM step (damped normal equations, Schur complement over the board poses)."""
        Ad = A.copy()
        Ad[np.diag_indices(nc)] += lam * np.maximum(np.diag(A), 1e-9)
        Ad[~free, :] = 0.0
        Ad[:, ~free] = 0.0
        Ad[~free, ~free] = 1.0
        Bf = B.copy()
        Bf[~free] = 0.0
        gaf = np.where(free, ga, 0.0)
        Cd = C.copy()
        idx = np.arange(6)
        Cd[:, idx, idx] += lam * np.maximum(C[:, idx, idx], 1e-12) + 1e-12
        Cinv = np.linalg.inv(Cd)
        B3 = Bf.reshape(nc, npose, 6).transpose(1, 0, 2)  # (P, nc, 6)
        BC = np.matmul(B3, Cinv)                           # (P, nc, 6)
        BC2 = BC.transpose(1, 0, 2).reshape(nc, 6 * npose)
        S = Ad - BC2 @ Bf.T                                # Bf (nc, 6P) is B3 laid out as BC2
        g3 = gb.reshape(npose, 6)
        rhs = gaf - BC2 @ gb
        dc = np.linalg.solve(S, rhs)
        db = np.matmul(Cinv, (g3 - (dc @ Bf).reshape(npose, 6))[:, :, None])[:, :, 0]
        return -dc, -db

    def apply(dc, db):
        ni = {c: intr[c] + dc[coff[c] : coff[c] + 4 + nd[c]] for c in cams}
        nR = {c: _exp(dc[coff[c] + 4 + nd[c] : coff[c] + 7 + nd[c]]) @ Rc[c] for c in cams}
        nt = {c: tc[c] + dc[coff[c] + 7 + nd[c] : coff[c] + 10 + nd[c]] for c in cams}
        nRb = np.stack([_exp(db[i, :3]) @ Rb[i] for i in range(npose)]) if npose else Rb
        return ni, nR, nt, nRb, tb + db[:, 3:]

    res, A, B, C, ga, gb = evaluate(intr, Rc, tc, Rb, tb, True, fs)
    add_prior(A, ga, intr)
    f = total_cost(res, intr)
    lam = 1e-12 if gauss_newton else 1e-5
    it = 0
    for it in range(1, max_iter + 1):
        progress.check()
        progress(min(0.95, it / max_iter), "joint refinement of all cameras and board poses")
        try:
            dc, db = solve(A, B, C, ga, gb, lam)
        except np.linalg.LinAlgError:
            lam *= 10.0
            continue
        cand = apply(dc, db)
        if gauss_newton:  # after the last step only the residuals are needed (unless the covariance is)
            intr, Rc, tc, Rb, tb = cand
            last = it == max_iter and not covariance
            res, A, B, C, ga, gb = evaluate(intr, Rc, tc, Rb, tb, not last, fs)
            if not last:
                add_prior(A, ga, intr)
            continue
        res_new = evaluate(*cand, False, fs)[0]
        f_new = total_cost(res_new, cand[0])
        if np.isfinite(f_new) and f_new <= f:
            rel = (f - f_new) / max(f, 1e-30)
            intr, Rc, tc, Rb, tb = cand
            f = f_new
            res, A, B, C, ga, gb = evaluate(intr, Rc, tc, Rb, tb, True, fs)
            add_prior(A, ga, intr)
            lam = max(lam / 10.0, 1e-12)
            if rel < tol:
                break
        else:
            lam *= 10.0
            if lam > 1e10:
                break

    allr = np.concatenate(list(res.values())) if res else np.zeros((0, 2))
    w = 1.0 / np.sqrt(1.0 + np.sum(allr**2, axis=1) / fs**2)
    n_free = int(free.sum()) + 6 * npose
    dof = max(1, 2 * n_pts - n_free)
    s2 = float(np.sum(w[:, None] * allr**2) / dof)
    cov: dict[str, np.ndarray] = {}
    cross: dict[tuple[str, str], np.ndarray] = {}
    cov_cb: dict[str, np.ndarray] = {}
    cov_bb = None
    if covariance:
        # covariance of the camera parameters: s^2 (A - B C^-1 B^T)^-1 over the free ones
        B3 = B.reshape(nc, npose, 6).transpose(1, 0, 2)
        Cinv = np.linalg.pinv(C)
        S = (A - np.matmul(B3, Cinv).transpose(1, 0, 2).reshape(nc, 6 * npose) @ B.T)[np.ix_(free, free)]
        # scale to unit diagonal before inverting: fx (1000s) and k3 (0.01s) differ by 1e6
        dsc = 1.0 / np.sqrt(np.maximum(np.diag(S), 1e-300))
        Sinv = dsc[:, None] * np.linalg.pinv(S * dsc[:, None] * dsc[None, :], rcond=1e-14, hermitian=True) * dsc[None, :]
        full = np.zeros((nc, nc))
        full[np.ix_(free, free)] = s2 * Sinv
        cov = {c: full[coff[c] : coff[c] + npar[c], coff[c] : coff[c] + npar[c]] for c in cams}
        cross = {(a, b): full[coff[a] : coff[a] + npar[a], coff[b] : coff[b] + npar[b]]
                 for a in cams for b in cams if a != b}
        # the inverse's other blocks: Cov_cb = -Cov_cc B C^-1, Cov_bb = s^2 C^-1 + C^-1 B^T Cov_cc B C^-1
        Bf = np.where(free[:, None], B, 0.0)
        M = np.einsum("ipj,pjk->ipk", Bf.reshape(nc, npose, 6), Cinv).reshape(nc, 6 * npose)
        cov_cb_all = -full @ M
        cov_bb = M.T @ full @ M
        for i in range(npose):
            cov_bb[6 * i : 6 * i + 6, 6 * i : 6 * i + 6] += s2 * Cinv[i]
        cov_cb = {c: cov_cb_all[coff[c] : coff[c] + npar[c]] for c in cams}
    out_cams = {}
    for c in cams:
        K = np.array([[intr[c][0], 0, intr[c][2]], [0, intr[c][1], intr[c][3]], [0, 0, 1.0]])
        out_cams[c] = (K, intr[c][4:].copy(), Rc[c].copy(), tc[c].copy())
    out_boards = {p: (Rb[i].copy(), tb[i].copy()) for p, i in pidx.items()}
    px = [res[c] * scale[c] for c in cams if c in res]
    allpx = np.concatenate(px) if px else np.zeros((0, 2))
    rms = float(np.sqrt(np.mean(np.sum(allpx**2, axis=1)))) if len(allpx) else float("nan")
    sigma_cam = {c: float(np.sqrt(np.mean((res[c] * scale[c]) ** 2))) for c in cams if c in res}
    residuals = {}
    for c in cams:
        if per_cam[c] is None:
            continue
        _o, _i, starts, _b, _pb, ks = per_cam[c]
        for m, k in enumerate(ks):
            e = starts[m + 1] if m + 1 < len(starts) else len(res[c])
            residuals[(obs[k][0], c)] = res[c][starts[m] : e] * scale[c]
    progress(1.0, "joint refinement done")
    return BundleResult(out_cams, out_boards, rms, float(np.sqrt(s2)), names, cov, cross, residuals, it, dof,
                        sigma_cam, poses, cov_cb, cov_bb)
