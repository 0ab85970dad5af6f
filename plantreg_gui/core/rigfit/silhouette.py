"""Fit source-camera poses to the plant's silhouette (edge alignment), optionally with landmarks.

The plant is easy to separate from the background in every modality (depth camera: valid depth
inside the ROI; a colour render: greener than the background; thermal: Otsu on temperature), and
its outline is the same physical curve in every camera up to parallax. This module:

1. takes the depth camera's plant outline (boundary pixels of its plant mask), gives each outline
   pixel the depth of the nearest pixel a few pixels *inside* the mask (the outline pixel's own
   depth is a flying pixel or missing at a leaf edge) and so gets 3D outline points ``X_rig``;
2. computes each source image's plant mask and its signed distance function ``sdf`` (pixels,
   > 0 outside the plant, < 0 inside, 0 on the outline; :func:`signed_distance`);
3. per source camera, jointly over all recordings, fits its pose so that ``sdf(project(X_rig))``
   is ~0, with a robust loss (outline points that the source camera sees inside the plant because
   of parallax or occlusion, a leaf that moved, a mask error, are down-weighted), one edge offset
   per recording (``bias_px``: the masks of two modalities need not put the edge at the same
   sub-pixel place — ToF mixed pixels shrink the depth mask, thermal blur grows or shrinks the
   thermal mask), weak priors towards the start pose, and optionally the landmark pairs with their
   click uncertainty.

``scipy.optimize.least_squares`` over a coarse-to-fine schedule of robust scales (large basin
first). Qt-free; progress and cancellation through :class:`~.progress.Reporter`.
Frames: ``X_cam = R_cam_rig @ X_rig + t_cam_rig``.
"""

from __future__ import annotations

import copy
import math
import time
from dataclasses import dataclass, field
from typing import Any, Sequence

import cv2
import numpy as np
from scipy.ndimage import distance_transform_edt, map_coordinates
from scipy.optimize import least_squares

from ..camera.camera import Camera
from ..errors import InputError
from ..progress import Reporter, ensure_reporter
from ..camera.rig import Rig


@dataclass
class SilhouetteParams:
    """Knobs of the silhouette fit (defaults chosen on the real Plant3DImageReg data by
    leave-one-plant-out landmark residuals, see docs/fit-rig.md)."""

    #: outline points per recording (evenly subsampled along the outline)
    max_points: int = 3000
    #: outline pixels take the depth of the nearest mask pixel this many pixels inside
    inset_px: int = 2
    #: smallest plant component kept in a mask, as a fraction of the image area
    min_component: float = 0.0005
    #: robust scales (px) of the coarse-to-fine schedule; the last one is the final fit's
    scales_px: tuple[float, ...] = (16.0, 6.0, 2.5)
    #: robust loss of the outline residuals: "cauchy" (redescending: a pot, a stem or a moved leaf
    #: that only one camera sees as plant stops pulling) or "soft_l1"
    loss: str = "cauchy"
    #: one recording's outline in one camera counts like this many independent landmark-like points
    #: (outline points are strongly correlated; this sets the silhouette's weight against landmarks)
    points_weight: float = 3.0
    #: assumed outline uncertainty (px) the silhouette residuals are divided by
    edge_px: float = 1.0
    #: prior sigma of the per-recording edge offset (px)
    bias_sigma_px: float = 2.0
    #: fit an edge offset per recording (else none)
    fit_bias: bool = True
    #: pose priors around the start rig (weak)
    rotation_deg: float = 5.0
    position_m: float = 0.05
    #: also fit the camera's focal length (fx, fy scaled together) with this prior sigma (relative)
    free_focal: bool = False
    focal_rel: float = 0.05
    #: landmark click uncertainty (px) per camera name; others use ``landmark_px_default``
    landmark_px: dict[str, float] = field(default_factory=dict)
    landmark_px_default: float = 1.5
    #: robust scale (px) for landmark residuals (Cauchy)
    landmark_robust_px: float = 3.0
    #: points projecting closer than this to the image border are not used (the mask is cut there)
    border_px: float = 4.0


# ---------------------------------------------------------------------- masks
def _components(mask: np.ndarray, min_area: int) -> np.ndarray:
    m = cv2.morphologyEx(mask.astype(np.uint8), cv2.MORPH_OPEN, np.ones((3, 3), np.uint8))
    n, lab, st, _ = cv2.connectedComponentsWithStats(m, connectivity=8)
    keep = np.zeros(n, bool)
    keep[1:] = st[1:, cv2.CC_STAT_AREA] >= min_area
    return keep[lab]


def depth_plant_mask(rig: Rig, depth_m: np.ndarray, min_component: float = 0.0005) -> np.ndarray:
    """bool (H, W): depth-camera pixels whose 3D point lies inside the rig's ROI (nearer than the
    ground), small components removed."""
    dcam = rig.depth()
    z = np.asarray(depth_m, np.float64)
    valid = np.isfinite(z) & (z > 0)
    X = dcam.rays_cam() * np.where(valid, z, 0).reshape(-1, 1)
    X = dcam.to_rig(X)
    inside = np.all((X >= rig.roi_min) & (X <= rig.roi_max), axis=1).reshape(z.shape) & valid
    return _components(inside, max(1, int(min_component * z.size)))


def source_plant_mask(img: np.ndarray, min_component: float = 0.0005) -> np.ndarray:
    """bool (H, W) plant mask of one source image.

    Colour (H, W, >=3, RGB): Otsu on green minus blue (leaves are greener than a blue, grey or white
    background). Single channel (thermal, a band): Otsu on the percentile-stretched, slightly
    blurred image, the plant being the class that is rarer along the image border."""
    a = np.asarray(img)
    if a.ndim == 3 and a.shape[2] >= 3:
        f = a[..., :3].astype(np.float32)
        x = f[..., 1] - f[..., 2]
    else:
        x = (a if a.ndim == 2 else a[..., 0]).astype(np.float32)
        x = cv2.GaussianBlur(x, (0, 0), 1.5)
    fin = np.isfinite(x)
    lo, hi = np.percentile(x[fin], [1, 99])
    x8 = np.clip((np.where(fin, x, lo) - lo) / max(hi - lo, 1e-9) * 255, 0, 255).astype(np.uint8)
    if a.ndim == 3:
        x8 = cv2.GaussianBlur(x8, (3, 3), 0)
    _, m = cv2.threshold(x8, 0, 1, cv2.THRESH_BINARY + cv2.THRESH_OTSU)
    if a.ndim != 3:
        b = np.concatenate([m[:4].ravel(), m[-4:].ravel(), m[:, :4].ravel(), m[:, -4:].ravel()])
        if b.mean() > 0.5:
            m = 1 - m
    return _components(m.astype(bool), max(1, int(min_component * m.size)))


def signed_distance(mask: np.ndarray) -> np.ndarray:
    """float32 (H, W) signed distance to the mask outline in pixels: > 0 outside, < 0 inside; the
    zero level lies half-way between the last plant pixel and the first background pixel (bilinear
    interpolation of this map crosses 0 there). The image border is not an outline."""
    m = mask.astype(np.uint8)
    out = cv2.distanceTransform(1 - m, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    inn = cv2.distanceTransform(m, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    if not m.any():
        out[:] = 1e3
    if m.all():
        inn[:] = 1e3
    return np.where(m > 0, -(inn - 0.5), out - 0.5).astype(np.float32)


def outline_points(rig: Rig, depth_m: np.ndarray, mask: np.ndarray, inset_px: int = 2,
                   max_points: int = 3000) -> np.ndarray:
    """3D outline points (N, 3), rig frame, of the depth camera's plant ``mask`` (H, W).

    Outline pixels = mask pixels with a 4-neighbour outside; each takes the depth of the nearest
    pixel of the mask eroded by ``inset_px`` (valid depth there), since the outline pixel's own
    depth is often a mixed (flying) value. Evenly subsampled to at most ``max_points``."""
    dcam = rig.depth()
    m = mask.astype(np.uint8)
    edge = m & (1 - cv2.erode(m, np.ones((3, 3), np.uint8), borderType=cv2.BORDER_CONSTANT, borderValue=0))
    z = np.asarray(depth_m, np.float64)
    core = cv2.erode(m, np.ones((3, 3), np.uint8), iterations=max(1, inset_px + 1)).astype(bool)
    core &= np.isfinite(z) & (z > 0)
    if not core.any() or not edge.any():
        return np.zeros((0, 3))
    _, idx = distance_transform_edt(~core, return_indices=True)
    vv, uu = np.nonzero(edge)
    # pixels on the depth image's own border are where the image cuts the plant, not an outline
    keep = (uu > 1) & (vv > 1) & (uu < m.shape[1] - 2) & (vv < m.shape[0] - 2)
    vv, uu = vv[keep], uu[keep]
    if len(uu) > max_points:
        sel = np.linspace(0, len(uu) - 1, max_points).round().astype(int)
        vv, uu = vv[sel], uu[sel]
    zz = z[idx[0][vv, uu], idx[1][vv, uu]]
    uv = np.stack([uu, vv], axis=1).astype(np.float64)
    X = dcam.rays_cam(uv) * zz[:, None]
    return dcam.to_rig(X)


def landmark_points(rig: Rig, depth_m: np.ndarray, depth_uv: np.ndarray, snap: bool = True
                    ) -> tuple[np.ndarray, np.ndarray]:
    """3D points (N, 3) rig frame of depth-camera pixels ``depth_uv`` (N, 2) at the depth the
    landmark fit gives them (:func:`.rigfit.check_landmark_depth`: a click that reads the ground
    beside a leaf is snapped onto the leaf, or left out without ``snap``); ``ok`` (N,) where a
    depth is used."""
    from .rigfit import check_landmark_depth

    dcam = rig.depth()
    uv = np.asarray(depth_uv, np.float64).reshape(-1, 2)
    z = np.array([check_landmark_depth(depth_m, p, rig.ground_z, snap).z_m for p in uv]) if len(uv) else np.zeros(0)
    ok = np.isfinite(z) & (z > 0)
    X = dcam.rays_cam(uv) * np.where(ok, z, 1.0)[:, None]
    return dcam.to_rig(X), ok


# ---------------------------------------------------------------------- inputs
@dataclass
class SilhouetteView:
    """One recording seen by one source camera: the depth camera's 3D outline points ``X_rig``
    (N, 3), the source image's signed distance map ``sdf`` (H, W) and optional landmarks:
    ``lm_X`` (L, 3) rig-frame points and ``lm_uv`` (L, 2) their pixels in the source camera."""

    name: str
    X_rig: np.ndarray
    sdf: np.ndarray
    lm_X: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    lm_uv: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))


def make_view(rig: Rig, camera: str, name: str, depth_m: np.ndarray, image: np.ndarray,
              params: SilhouetteParams | None = None, depth_mask: np.ndarray | None = None,
              source_mask: np.ndarray | None = None) -> SilhouetteView:
    """Build one :class:`SilhouetteView` from a recording's depth (metres) and the camera's image;
    masks are computed unless given (bool, the depth map's / the image's size)."""
    p = params or SilhouetteParams()
    cam = rig.camera(camera)
    if image.shape[:2] != cam.shape:
        raise InputError(f"{name}: image of '{camera}' is {image.shape[1]}x{image.shape[0]}, "
                         f"the rig says {cam.width}x{cam.height}")
    dm = depth_plant_mask(rig, depth_m, p.min_component) if depth_mask is None else depth_mask
    sm = source_plant_mask(image, p.min_component) if source_mask is None else source_mask
    X = outline_points(rig, depth_m, dm, p.inset_px, p.max_points)
    return SilhouetteView(name, X, signed_distance(sm))


# ---------------------------------------------------------------------- the fit
@dataclass
class SilhouetteResult:
    """``camera`` the fitted camera; ``report`` JSON-able."""

    camera: Camera
    report: dict[str, Any]
    warnings: list[str] = field(default_factory=list)


def _camera_at(base: Camera, x: np.ndarray, log_focal: float = 0.0) -> Camera:
    """Camera with rotation ``exp(x[:3]) @ base.R``, optical centre ``x[3:6]`` (rig frame) and
    focal lengths scaled by ``exp(log_focal)``."""
    cam = copy.deepcopy(base)
    cam.K[0, 0] *= math.exp(log_focal)
    cam.K[1, 1] *= math.exp(log_focal)
    R = cv2.Rodrigues(np.asarray(x[:3], np.float64))[0] @ base.R_cam_rig
    cam.R_cam_rig, cam.t_cam_rig = R, -R @ np.asarray(x[3:6], np.float64)
    return cam


def _sample(sdf: np.ndarray, uv: np.ndarray) -> np.ndarray:
    return map_coordinates(sdf, [uv[:, 1], uv[:, 0]], order=1, mode="nearest")


def _robust(r: np.ndarray, s: float) -> np.ndarray:
    """Residual transformed so that its square is the soft-L1 loss with scale ``s``."""
    a = r / s
    return np.sign(r) * s * np.sqrt(2.0 * (np.sqrt(1.0 + a * a) - 1.0))


def _cauchy(r: np.ndarray, s: float) -> np.ndarray:
    """Transformed residual (..., k) whose squared norm is the Cauchy loss of the point's distance."""
    d = np.linalg.norm(r, axis=-1, keepdims=True)
    return r * np.where(d > 0, s * np.sqrt(np.log1p((d / s) ** 2)) / np.maximum(d, 1e-12), 1.0)


def fit_camera(rig: Rig, camera: str, views: Sequence[SilhouetteView], params: SilhouetteParams | None = None,
               use_silhouette: bool = True, progress: Reporter | None = None) -> SilhouetteResult:
    """Fit ``camera``'s pose to the outlines (and landmarks) of ``views``, starting from ``rig``.

    Returns the fitted camera and a report: ``start``/``end`` robust cost, per view the median
    absolute outline distance (px) of the points used and the fitted edge offset, the pose change,
    landmark residuals before and after. ``use_silhouette=False`` fits the landmarks alone with the
    same priors (for comparison)."""
    p = params or SilhouetteParams()
    progress = ensure_reporter(progress)
    t0 = time.perf_counter()
    base = rig.camera(camera)
    sig_lm = p.landmark_px.get(camera, p.landmark_px_default)
    nv = len(views)
    nb = nv if (p.fit_bias and use_silhouette) else 0
    nf = 1 if p.free_focal else 0
    x0 = np.concatenate([np.zeros(3), base.center_rig, np.zeros(nb + nf)])

    def cam_of(x: np.ndarray) -> Camera:
        return _camera_at(base, x, x[6 + nb] if nf else 0.0)
    n_lm = sum(len(v.lm_uv) for v in views)
    if not use_silhouette and n_lm < 6:
        raise InputError(f"{camera}: {n_lm} landmarks, fewer than the 6 a pose needs")
    if use_silhouette and not any(len(v.X_rig) for v in views):
        raise InputError(f"{camera}: no plant outline in any recording (empty depth mask?)")
    # per-view landmark outliers are decided once against the start pose ordering: none dropped here,
    # the Cauchy loss bounds their pull
    h, w = base.shape

    def residuals(x: np.ndarray, active: list[np.ndarray], scale: float) -> np.ndarray:
        progress.check()  # a cancellation point per evaluation (each is milliseconds)
        cam = cam_of(x)
        out = []
        if use_silhouette:
            for i, v in enumerate(views):
                X = v.X_rig[active[i]]
                if not len(X):
                    continue
                uv, _ = cam.project(X)
                uv = np.nan_to_num(uv, nan=-1e3)
                r = _sample(v.sdf, uv) - (x[6 + i] if nb else 0.0)
                wgt = math.sqrt(p.points_weight / len(X)) / p.edge_px
                rr = _cauchy(r[:, None], scale)[:, 0] if p.loss == "cauchy" else _robust(r, scale)
                out.append(rr * wgt)
        for v in views:
            if len(v.lm_uv):
                uv, _ = cam.project(v.lm_X)
                r = (np.nan_to_num(uv, nan=1e4) - v.lm_uv)
                out.append((_cauchy(r, p.landmark_robust_px) / sig_lm).ravel())
        pri = [x[:3] / math.radians(p.rotation_deg), (x[3:6] - base.center_rig) / p.position_m]
        if nb:
            pri.append(x[6:6 + nb] / p.bias_sigma_px)
        if nf:
            pri.append(x[6 + nb:] / p.focal_rel)
        out += pri
        return np.concatenate(out)

    def active_sets(x: np.ndarray) -> list[np.ndarray]:
        cam = cam_of(x)
        act = []
        for v in views:
            uv, z = cam.project(v.X_rig)
            act.append(cam.in_image(np.nan_to_num(uv, nan=-1e3), margin=p.border_px) & (z > 0))
        return act

    x = x0.copy()
    start_cost = None
    nfev = 0
    scales = p.scales_px if use_silhouette else p.scales_px[-1:]
    for k, s in enumerate(scales):
        progress(k / len(scales), f"{camera}: silhouette fit at {s:g} px")
        act = active_sets(x)
        if start_cost is None:
            start_cost = float(np.sum(residuals(x, act, scales[-1]) ** 2))
        res = least_squares(residuals, x, args=(act, s), method="trf", x_scale="jac", max_nfev=60)
        x, nfev = res.x, nfev + res.nfev
    act = active_sets(x)
    end_cost = float(np.sum(residuals(x, act, scales[-1]) ** 2))
    cam = cam_of(x)
    per_view = {}
    for i, v in enumerate(views):
        e: dict[str, Any] = {"points": int(act[i].sum())}
        if use_silhouette and act[i].any():
            uv, _ = cam.project(v.X_rig[act[i]])
            d = np.abs(_sample(v.sdf, uv) - (x[6 + i] if nb else 0.0))
            e["outline_median_px"] = float(np.median(d))
            e["outline_within_2px"] = float(np.mean(d < 2.0))
            e["edge_offset_px"] = float(x[6 + i]) if nb else 0.0
        if len(v.lm_uv):
            e["landmarks_px"] = landmark_errors(base, v).tolist()
            e["landmarks_px_after"] = landmark_errors(cam, v).tolist()
        per_view[v.name] = e
    dR = cv2.Rodrigues(cam.R_cam_rig @ base.R_cam_rig.T)[0]
    report = {"camera": camera, "start_cost": start_cost, "end_cost": end_cost, "evaluations": int(nfev),
              "rotation_change_deg": float(np.degrees(np.linalg.norm(dR))),
              "position_change_m": float(np.linalg.norm(cam.center_rig - base.center_rig)),
              "focal_change_rel": float(math.exp(x[6 + nb]) - 1.0) if nf else 0.0,
              "views": per_view, "silhouette": use_silhouette, "landmarks": n_lm,
              "seconds": round(time.perf_counter() - t0, 2)}
    progress(1.0, f"{camera}: silhouette fit done")
    return SilhouetteResult(cam, report)


def landmark_errors(cam: Camera, view: SilhouetteView) -> np.ndarray:
    """Pixel distance (L,) between projected landmark points and their clicks in ``cam``."""
    if not len(view.lm_uv):
        return np.zeros(0)
    uv, _ = cam.project(view.lm_X)
    return np.linalg.norm(uv - view.lm_uv, axis=1)


def fit_rig_silhouette(rig: Rig, views: dict[str, Sequence[SilhouetteView]], params: SilhouetteParams | None = None,
                       progress: Reporter | None = None) -> tuple[Rig, dict[str, Any]]:
    """Fit every camera in ``views`` (camera name -> its views) and return the new rig (a copy)
    and a report per camera; the fitted rig's ``extra["calibration"]["silhouette"]`` holds it."""
    progress = ensure_reporter(progress)
    out = copy.deepcopy(rig)
    report: dict[str, Any] = {"method": "silhouette signed-distance fit", "cameras": {}}
    names = list(views)
    for i, name in enumerate(names):
        r = fit_camera(rig, name, views[name], params, progress=progress.sub(i / len(names), (i + 1) / len(names)))
        out.cameras = [r.camera if c.name == name else c for c in out.cameras]
        report["cameras"][name] = r.report
    calib = dict(out.extra.get("calibration", {})) if isinstance(out.extra.get("calibration"), dict) else {}
    calib["silhouette"] = report
    out.extra["calibration"] = calib
    return out, report


def fit_rig_recordings(rig: Rig, recordings: Sequence[Any], landmarks: dict[str, Sequence[Any]] | None = None,
                       cameras: Sequence[str] | None = None, params: SilhouetteParams | None = None,
                       progress: Reporter | None = None, snap_depth: bool = True) -> tuple[Rig, dict[str, Any]]:
    """:func:`fit_rig_silhouette` on loaded recordings (:class:`~.recording.Recording`).

    ``landmarks``: recording folder (resolved absolute path, str) -> its landmark points
    (:class:`~.landmarks.Landmark`), used as a term of the fit with their click uncertainty;
    ``cameras``: default every camera but the depth camera that some recording has an image of;
    ``snap_depth``: as ``fit-rig`` (a landmark reading the ground is snapped, else left out)."""
    progress = ensure_reporter(progress)
    p = params or SilhouetteParams()
    dcam = rig.depth()
    names = list(cameras) if cameras is not None else [
        c.name for c in rig.cameras if c.name != dcam.name and any(c.name in r.images for r in recordings)]
    views: dict[str, list[SilhouetteView]] = {n: [] for n in names}
    for i, rec in enumerate(recordings):
        progress(0.2 * i / max(1, len(recordings)), "silhouette fit: plant outlines")
        rec.check(rig)
        depth_m = rec.depth_m(rig.depth_scale)
        dmask = depth_plant_mask(rig, depth_m, p.min_component)
        X = outline_points(rig, depth_m, dmask, p.inset_px, p.max_points)
        key = str(rec.folder.resolve()) if rec.folder is not None else f"recording {i + 1}"
        pts = list((landmarks or {}).get(key, []))
        for n in names:
            if n not in rec.images:
                continue
            v = SilhouetteView(key, X, signed_distance(source_plant_mask(rec.images[n], p.min_component)))
            mine = [lm for lm in pts if n in lm.cameras]
            if mine:
                lX, ok = landmark_points(rig, depth_m, np.array([lm.depth_uv for lm in mine]), snap_depth)
                v.lm_X, v.lm_uv = lX[ok], np.array([lm.cameras[n] for lm in mine])[ok]
            views[n].append(v)
    return fit_rig_silhouette(rig, {n: v for n, v in views.items() if v}, p, progress.sub(0.2, 1.0))


def outline_agreement(cam: Camera, view: SilhouetteView, near_px: float = 4.0,
                      border_px: float = 4.0) -> dict[str, Any]:
    """How well ``cam`` puts the depth camera's outline on the source image's outline: a check that
    needs no landmarks. Over outline points projecting inside the image: ``median_abs_px`` and
    ``within_2px`` of the signed distance, and a least-squares fit ``d = offset + n . shift`` over
    the points within ``near_px`` (``n`` the source outline's outward normal): ``shift_px`` (u, v)
    is the image translation the outlines imply for this recording (0 = consistent), ``offset_px``
    the edge offset between the two modalities' masks."""
    uv, z = cam.project(view.X_rig)
    ok = cam.in_image(np.nan_to_num(uv, nan=-1e3), margin=border_px) & (z > 0)
    if ok.sum() < 10:
        return {"points": int(ok.sum())}
    uv = uv[ok]
    d = _sample(view.sdf, uv)
    gy, gx = np.gradient(cv2.GaussianBlur(view.sdf, (0, 0), 1.0))
    n = np.stack([_sample(gx, uv), _sample(gy, uv)], axis=1)
    sel = np.abs(d) < near_px
    out: dict[str, Any] = {"points": int(ok.sum()), "median_abs_px": float(np.median(np.abs(d))),
                           "within_2px": float(np.mean(np.abs(d) < 2.0))}
    if sel.sum() >= 10:
        A = np.concatenate([np.ones((int(sel.sum()), 1)), n[sel]], axis=1)
        sol = np.linalg.lstsq(A, d[sel], rcond=None)[0]
        out["offset_px"], out["shift_px"] = float(sol[0]), [float(sol[1]), float(sol[2])]
    return out
