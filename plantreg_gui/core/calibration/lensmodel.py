"""Each camera's lens model, chosen by how well it predicts board views it was not fitted to.

Candidates, simplest first (OpenCV's distortion model with some terms held at zero):

=============  ==========================================================
``k1k2``       k1, k2
``k1k2-tan``   k1, k2, p1, p2
``k1k2k3-tan`` k1, k2, p1, p2, k3 (OpenCV's default 5 coefficients)
``rational``   k1..k6, p1, p2 (8 coefficients, wide-angle lenses)
=============  ==========================================================

Leave-views-out cross-validation per camera (intrinsics only): the views are split into folds
(one view per fold up to 8 views, else ``CV_FOLDS``); each candidate is fitted on the other folds
(the bundle adjustment of :mod:`.bundle` with this camera alone, started from its fit to all views) and every held-out view is predicted with it: its board pose from the
view's own corners (PnP), the error is the RMS distance of its corners. The chosen model is the
simplest whose cross-validated error is within ``CV_TOLERANCE`` of the best one's: a richer
model must predict unseen views clearly better to be believed (with few or poorly spread views
the extra terms fit noise and extrapolate wildly, e.g. k3 = -15 and a principal point 200 px
off-centre). Candidates with more parameters than the views can determine are not tried.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np

from ..errors import InputError
from .bundle import CameraBlock, bundle_adjust

CV_FOLDS = 5
#: the principal point's prior: the image centre, with this standard error as a fraction of the
#: image diagonal (about the spread of real cameras' principal points)
PP_PRIOR_FRAC = 0.02
#: a richer model is chosen only if it predicts held-out views better by more than this
#: fraction (cross-validated RMS error)
CV_TOLERANCE = 0.03


def principal_point_prior(size: tuple[int, int]) -> dict[str, tuple[float, float]]:
    """Prior {"cx": (value, std), "cy": ...} of a ``size`` (w, h) camera's principal point."""
    w, h = size
    sd = PP_PRIOR_FRAC * float(np.hypot(w, h))
    return {"cx": ((w - 1) / 2.0, sd), "cy": ((h - 1) / 2.0, sd)}

_BASE = cv2.CALIB_FIX_K3 | cv2.CALIB_ZERO_TANGENT_DIST


@dataclass(frozen=True)
class LensModel:
    """One candidate: ``name``, OpenCV ``flags``, ``nd`` distortion coefficients in the vector,
    ``fixed`` parameter names held (at 0, or at the image centre for cx/cy), ``label`` for people."""

    name: str
    flags: int
    nd: int
    fixed: frozenset
    label: str

    @property
    def n_params(self) -> int:
        return 4 + self.nd - len(self.fixed)


MODELS = (
    LensModel("k1k2", _BASE, 5, frozenset({"p1", "p2", "k3"}), "k1, k2"),
    LensModel("k1k2-tan", cv2.CALIB_FIX_K3, 5, frozenset({"k3"}), "k1, k2, p1, p2"),
    LensModel("k1k2k3-tan", 0, 5, frozenset(), "k1, k2, p1, p2, k3"),
    LensModel("rational", cv2.CALIB_RATIONAL_MODEL, 8, frozenset(), "k1..k6, p1, p2 (rational)"),
)
MODEL_BY_NAME = {m.name: m for m in MODELS}


@dataclass
class ModelChoice:
    """The chosen model and why: ``cv_px`` model name -> cross-validated RMS error (px) of the
    held-out views (None: not tried, ``skipped`` says why), ``fit_px`` name -> RMS on all views."""

    model: LensModel
    cv_px: dict[str, float | None]
    fit_px: dict[str, float]
    n_folds: int
    reason: str
    skipped: dict[str, str] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return {"model": self.model.name, "label": self.model.label, "reason": self.reason,
                "cv_rms_px": self.cv_px, "fit_rms_px": self.fit_px, "folds": self.n_folds,
                "skipped": self.skipped}


def _dist_vector(dist: np.ndarray, nd: int) -> np.ndarray:
    d = np.zeros(nd)
    v = np.asarray(dist, float).ravel()[:nd]
    d[: len(v)] = v
    return d


def _pnp(obj: np.ndarray, img: np.ndarray, K: np.ndarray, dist: np.ndarray, init=None):
    """Board pose (rvec, tvec) of one view under a model."""
    if init is not None:
        ok, rv, tv = cv2.solvePnP(obj, img, K, dist, cv2.Rodrigues(init[0])[0], init[1].reshape(3, 1).copy(), True)
    else:
        ok, rv, tv = cv2.solvePnP(obj, img, K, dist)
    return cv2.solvePnPRefineLM(obj, img, K, dist, rv, tv)


def _sq_errors(obj, img, K, dist, init=None) -> np.ndarray:
    """Squared corner distances (N,) of one view predicted by a model (its pose from PnP)."""
    rv, tv = _pnp(obj, img, K, dist, init)
    proj = cv2.projectPoints(obj, rv, tv, K, dist)[0].reshape(-1, 2)
    return np.sum((proj - img) ** 2, axis=1)


def fit_camera(obj: list[np.ndarray], img: list[np.ndarray], model: LensModel, K0: np.ndarray,
               dist0: np.ndarray, poses0: list[tuple[np.ndarray, np.ndarray]], max_iter: int = 50,
               tol: float = 1e-10, size: tuple[int, int] | None = None, gauss_newton: bool = False):
    """Fit one camera's ``model`` to its views (``obj`` [(N, 3)], ``img`` [(N, 2)]) from a start
    (``poses0`` [(R_cam_board, t_cam_board)]) by the bundle adjustment (:mod:`.bundle`) with
    this camera alone. Returns (rms px, K, dist (nd,), poses [(R, t)])."""
    blk = CameraBlock(np.asarray(K0, float), _dist_vector(dist0, model.nd), np.eye(3), np.zeros(3),
                      fixed=set(model.fixed), prior=principal_point_prior(size) if size else {})
    init = {f"{i:05d}": (np.asarray(R, float), np.asarray(t, float).ravel()) for i, (R, t) in enumerate(poses0)}
    obs = [(f"{i:05d}", "c", o, m) for i, (o, m) in enumerate(zip(obj, img))]
    r = bundle_adjust(["c"], "c", {"c": blk}, init, obs, max_iter=max_iter, covariance=False, tol=tol,
                      gauss_newton=gauss_newton)
    K, dist, _R, _t = r.cams["c"]
    return r.rms_px, K, dist, [r.boards[f"{i:05d}"] for i in range(len(obj))]


def focal_rel_std(obj: list[np.ndarray], img: list[np.ndarray], model: LensModel, fit: tuple,
                  size: tuple[int, int]) -> float:
    """Relative standard error of fx of a camera fitted to its own views alone (``fit`` from
    :func:`choose_model`): how well its views determine its own focal length (fronto-parallel
    views, or boards tilted about one axis only, leave it undetermined)."""
    _rms, K, dist, poses = fit
    blk = CameraBlock(np.asarray(K, float), _dist_vector(dist, model.nd), np.eye(3), np.zeros(3),
                      fixed=set(model.fixed), prior=principal_point_prior(size))
    init = {f"{i:05d}": (np.asarray(R, float), np.asarray(t, float).ravel()) for i, (R, t) in enumerate(poses)}
    obs = [(f"{i:05d}", "c", np.asarray(o, float).reshape(-1, 3), np.asarray(m, float).reshape(-1, 2))
           for i, (o, m) in enumerate(zip(obj, img))]
    r = bundle_adjust(["c"], "c", {"c": blk}, init, obs, max_iter=0)
    sd = float(np.sqrt(max(r.cov["c"][0, 0], 0.0)))
    return sd / max(abs(float(K[0, 0])), 1e-9)


def choose_model(name: str, obj: list[np.ndarray], img: list[np.ndarray], size: tuple[int, int],
                 candidates: tuple[LensModel, ...] = MODELS, rng_seed: int = 0) -> tuple[ModelChoice, tuple]:
    """Cross-validate ``candidates`` (nested, simplest first) on one camera's views (``obj``
    [(N, 3)], ``img`` [(N, 2)]) and return the choice and ``(rms, K, dist (nd,), poses
    [(R_cam_board, t_cam_board)])`` of the chosen model fitted to all views."""
    n = len(obj)
    obj = [np.asarray(o, np.float64).reshape(-1, 3) for o in obj]
    img = [np.asarray(m, np.float64).reshape(-1, 2) for m in img]
    n_pts = sum(len(o) for o in obj)
    w, h = size
    # start: focal length from the views' homographies, principal point at the centre, no distortion
    try:
        K = cv2.initCameraMatrix2D([o.astype(np.float32) for o in obj], [m.astype(np.float32) for m in img], size)
    except cv2.error:
        K = np.array([[float(max(w, h)), 0, 0], [0, float(max(w, h)), 0], [0, 0, 1.0]])
    K = np.asarray(K, float)
    K[0, 2], K[1, 2] = (w - 1) / 2.0, (h - 1) / 2.0
    dist = np.zeros(5)
    poses = []
    for o, m in zip(obj, img):
        rv, tv = _pnp(o, m, K, dist)
        poses.append((cv2.Rodrigues(rv)[0], tv.ravel()))
    fits: dict[str, tuple] = {}
    skipped: dict[str, str] = {}
    for m in candidates:
        # every view adds 6 pose unknowns; keep 3 observations per unknown at least
        if 2 * n_pts < 3 * (m.n_params + 6 * n):
            skipped[m.name] = f"{m.n_params} lens parameters need more corners than {n} views give"
            continue
        if m.name == "rational" and n < 8:
            skipped[m.name] = f"needs 8 views or more ({n})"
            continue
        try:
            fit = fit_camera(obj, img, m, K, dist, poses, tol=1e-8, size=size)
        except (np.linalg.LinAlgError, cv2.error):
            skipped[m.name] = "the fit failed"
            continue
        if not (np.isfinite(fit[0]) and np.all(np.isfinite(fit[1])) and np.all(np.isfinite(fit[2]))):
            skipped[m.name] = "the fit diverged"
            continue
        fits[m.name] = fit
        _rms, K, dist, poses = fit  # the next (richer) model starts here
    if not fits:
        raise InputError(f"camera '{name}': could not calibrate it from its {n} views")
    tried = [m for m in candidates if m.name in fits]
    fit_px = {k: v[0] for k, v in fits.items()}
    if n < 4 or len(tried) == 1:
        m = tried[0]
        reason = (f"{n} views are too few to cross-validate: the simplest model" if n < 4
                  else "the only model the views determine")
        return ModelChoice(m, {x.name: None for x in candidates}, fit_px, 0, reason, skipped), fits[m.name]
    k = n if n <= 8 else CV_FOLDS
    order = np.random.default_rng(rng_seed).permutation(n)
    folds = [np.sort(order[i::k]) for i in range(k)]
    cv_px: dict[str, float | None] = {m.name: None for m in candidates}
    per_view: dict[str, np.ndarray] = {}
    for m in tried:
        _rms, K_all, d_all, p_all = fits[m.name]
        mse = np.full(n, np.nan)
        for f in folds:
            held = set(f.tolist())
            train = [i for i in range(n) if i not in held]
            try:
                _r, Kf, df, _p = fit_camera([obj[i] for i in train], [img[i] for i in train], m, K_all, d_all,
                                            [p_all[i] for i in train], max_iter=3, size=size, gauss_newton=True)
                for i in f:
                    mse[i] = float(np.mean(_sq_errors(obj[i], img[i], Kf, df, p_all[i])))
            except (np.linalg.LinAlgError, cv2.error):
                mse[:] = np.nan
                break
        if np.all(np.isfinite(mse)):
            per_view[m.name] = mse
            cv_px[m.name] = float(np.sqrt(np.average(mse, weights=[len(o) for o in obj])))
    scored = [m for m in tried if m.name in per_view]
    if not scored:
        m = tried[0]
        return ModelChoice(m, cv_px, fit_px, k, "cross-validation failed for every model: the simplest",
                           skipped), fits[m.name]
    best_m = min(scored, key=lambda m: cv_px[m.name])
    best = cv_px[best_m.name]
    chosen = next(m for m in scored if cv_px[m.name] <= best * (1.0 + CV_TOLERANCE))
    if chosen is best_m:
        reason = f"predicts held-out views best ({cv_px[chosen.name]:.3f} px)"
    else:
        reason = (f"predicts held-out views within {100 * CV_TOLERANCE:g} % of the best "
                  f"({cv_px[chosen.name]:.3f} px vs {best:.3f} px for {best_m.label}) with fewer parameters")
    return ModelChoice(chosen, cv_px, fit_px, k, reason, skipped), fits[chosen.name]
