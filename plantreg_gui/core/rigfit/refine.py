"""Automatic, target-less refinement of a rig from its recordings (issue 8, item 2).

Each source camera's pose (and, if asked, its focal length) is refined by maximising the
statistical dependence between that camera's image and what the depth camera saw, over several
recordings at once -- the idea of koide3's ``direct_visual_lidar_calibration`` (normalised
information distance between an image and range data), with the depth camera's own infrared
image and its measured 3D points instead of a lidar's intensities.

Objective (per source camera, documented for users in ``docs/refine.md``):

* Points: the depth camera's pixels back-projected through its intrinsics and distortion
  (``X_rig`` (N, 3), exactly the vertices of the registration's object mesh, plus the measured
  background such as the ground, which carries texture too). Excluded: pixels without depth,
  pixels next to a depth jump (mixed / flying pixels: the P3.1 and P5 areas of the registration),
  and points the source cannot see for certain at the current pose: a ray from the source camera
  centre towards the point that meets the object mesh (P2) or the uncertainty mesh (P3.2) more
  than ``occlusion_tol_m`` before it (the registration's own meshes and ray caster,
  :func:`~.register.build_meshes`). Visibility is recomputed at the start of every scale level.
* Values: the reference value of a point is the depth camera's own image (infrared) at its
  pixel (the depth map itself if the depth camera has no image); the source value is the
  source image sampled bilinearly where the point projects with the candidate pose. Images with
  several channels (RGB, hyperspectral) are reduced to their first principal component.
* Similarity: normalised information distance ``NID = 1 - I(R; S) / H(R, S)`` of a joint
  histogram per recording (reference: equal-population bins; source: the same, with linear
  soft binning so that the cost is continuous in the pose), averaged over the recordings
  weighted by their point counts. Histograms per recording make the cost indifferent to a
  source whose levels change between recordings (a warmer day).
* Multi-scale: both images are blurred with a Gaussian whose width is a fixed *angle* per
  level (``RefineParams.levels_deg``), so every camera is captured from the same angular error;
  fewer points are used at coarse levels. Powell's method (scipy) per level, in parameters
  scaled so that one unit moves the image by one blur width: rotation (image x, y, roll), a
  translation whose first-order image shift at the points' median depth is cancelled by a
  rotation (so that it only moves near and far points against each other -- rotation and
  translation no longer trade off), a z translation (with the focal length compensating its
  scale at the median depth when the focal length is free) and, optionally, the focal length.

A camera is reported *converged* when the finest level's optimiser converged inside its bounds
and the cost has a real minimum there: the NID at the result lies clearly below the NID of the
same points with the reference values shuffled (chance) and below the NID with the pose moved
by a few pixels. A uniform or unrelated image fails the test and gets a warning.

Length: one optimisation (agreement of registered images under pose changes) with its cost,
its fast re-projection and its safeguards; splitting it would scatter one algorithm.
"""

from __future__ import annotations

import copy
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Any, Callable, Sequence

import cv2
import numpy as np

from ..camera.camera import Camera
from ..errors import InputError
from ..progress import CancelToken, Reporter, ensure_reporter
from ..camera.camera import _has_tilt, distort_normalized
from ..geometry.raycast import pixel_rays_cam
from ..data.recording import Recording
from ..registration.params import RegistrationParams
from ..registration.register import Meshes, build_meshes, filter_depth
from ..registration.transport import transport_pixels
from ..camera.rig import Rig

#: one visibility query on the shared meshes at a time (each is parallel inside Open3D)
_RAYCAST_LOCK = threading.Lock()

#: what ``free`` may contain (other names are accepted by the caller's landmark fit, not here)
REFINABLE = frozenset({"focal"})

#: landmark pairs of one camera in one recording: depth-camera pixels (N, 2), the camera's pixels (N, 2)
LandmarkPairs = tuple[np.ndarray, np.ndarray]
#: ``landmarks(recording_index, camera_name) -> LandmarkPairs | None``
LandmarkSource = Callable[[int, str], "LandmarkPairs | None"]


@dataclass
class RefineParams:
    """Tuning of :func:`refine_rig` (defaults measured on the demo rig; see docs/refine.md)."""

    #: blur per level as an angle (degrees); 0 = the finest level (``min_sigma_px`` source pixels)
    levels_deg: tuple[float, ...] = (1.6, 0.8, 0.4, 0.2, 0.0)
    min_sigma_px: float = 0.8
    bins: int = 24                      # histogram bins per axis
    max_points: int = 15000            # per recording at the finest level (6000 was measured too few for thermal)
    min_points: int = 3000              # per recording at the coarsest level
    candidates: int = 8                 # depth points considered per recording, in multiples of max_points
    bound_units: float = 5.0            # search box per level, +- blur widths
    depth_jump_m: float = 0.01          # a 3x3 depth range above max(this, 1.5 % of depth) = mixed pixel
    occlusion_tol_m: float = 0.002      # as RegistrationParams.occlusion_tol_m
    visibility_radius_m: float = 0.04   # points hidden from any centre this far from the estimate are left out
    xtol: float = 0.05                  # Powell at the finest level, in blur widths (5x at coarser ones)
    max_translation_m: float = 0.05     # per level, bounds the translation search
    max_focal: float = 0.06             # per level, bounds the focal search (relative)
    maxfev_per_param: int = 120         # Powell's evaluations per searched parameter and level
    restarts: int = 2                   # Powell restarts when it runs out of evaluations
    #: converged only if the chance NID minus the result's NID is at least this
    min_information: float = 0.01
    #: ... and moving the image by max(``probe_px``, 1 % of its diagonal) either way in x and y raises
    #: the NID by at least this fraction of that information
    min_contrast: float = 0.01
    probe_px: float = 3.0               # at least this, or probe_frac of the image diagonal
    probe_frac: float = 0.01
    #: landmark disagreement (median px) above which a warning is given
    landmark_warn_px: float = 3.0
    #: ... and if the landmarks agreed better with the start pose, keep the start pose
    keep_if_landmarks_disagree: bool = True
    seed: int = 0
    #: cameras refined at the same time (threads: numpy, OpenCV and Open3D release the GIL in the
    #: cost's heavy calls). The result does not depend on it; 1 = one after the other.
    workers: int = 2
    # Experiment hooks (None: the method as documented). For evaluating variants of the method
    # (resources/plant3dimagereg/landmark_scripts/refine_eval.py) without patching this module.
    #: (image (H, W) float32, sigma px) -> the filtered image both sides are compared in (default: Gaussian blur)
    image_filter: Callable[[np.ndarray, float], np.ndarray] | None = None
    #: (level, number of levels, focal free) -> the parameters searched at that level
    active_params: Callable[[int, int, bool], list[int]] | None = None
    #: (points X_rig (N, 3), roi (lo, hi), weights (N,)) -> the level's point weights
    point_weights: Callable[[np.ndarray, tuple[np.ndarray, np.ndarray], np.ndarray], np.ndarray] | None = None
    #: camera -> a term added to the cost (e.g. a landmark residual)
    extra_cost: Callable[[Camera], float] | None = None


@dataclass
class RefineResult:
    """``rig``: refined copy of the input rig; ``report``: JSON-able per-camera figures (see
    :func:`refine_rig`); ``warnings``: one line each, camera name first."""

    rig: Rig
    report: dict[str, Any]
    warnings: list[str] = field(default_factory=list)


# ---------------------------------------------------------------------------- landmarks (thin coupling)
def landmark_source(landmarks: Any, recordings: Sequence[Recording]) -> LandmarkSource | None:
    """Adapt ``landmarks`` to ``f(recording_index, camera) -> (depth_uv (N, 2), cam_uv (N, 2)) | None``.

    Accepted (duck-typed, so that the landmark module stays independent of this one):

    * ``None`` -> ``None``;
    * a callable ``f(recording_index, camera)`` -> returned as is;
    * an object with ``pairs(recording_index, camera)`` -> its bound method;
    * a sequence with one entry per recording, each a list of points;
    * a mapping ``{key: points}`` or an object with ``.recordings`` of that shape (the landmarks
      file's ``"recordings"``; a ``{"points": [...]}`` wrapper is unwrapped), where a key
      matches a recording when the recording's folder path ends with it.

    A point is a mapping or an object with ``depth_uv`` (2,) and ``cameras`` {camera: (2,)}.
    """
    if landmarks is None:
        return None
    if hasattr(landmarks, "pairs") and callable(landmarks.pairs):
        return landmarks.pairs
    if callable(landmarks):
        return landmarks
    recs = getattr(landmarks, "recordings", landmarks)
    if isinstance(recs, dict) and "recordings" in recs and isinstance(recs["recordings"], dict):
        recs = recs["recordings"]
    per_rec: list[list[Any]] = [[] for _ in recordings]
    if isinstance(recs, dict):
        folder_of = getattr(landmarks, "folder", None)  # a LandmarkSet resolves its own keys
        for key, pts in recs.items():
            if callable(folder_of):
                key = str(folder_of(key).resolve())
            kparts = [p for p in str(key).replace("\\", "/").split("/") if p not in ("", ".")]
            for i, rec in enumerate(recordings):
                if rec.folder is None:
                    continue
                rparts = [p for p in rec.folder.resolve().as_posix().split("/") if p]
                if kparts and kparts == rparts[-len(kparts):]:
                    per_rec[i] = _points_of(pts)
    elif isinstance(recs, (list, tuple)):
        if len(recs) != len(recordings):
            raise InputError(f"landmarks give {len(recs)} recordings but {len(recordings)} were loaded")
        per_rec = [_points_of(p) for p in recs]
    else:
        raise InputError(f"landmarks of type {type(landmarks).__name__} are not understood")

    def pairs(i: int, cam: str) -> LandmarkPairs | None:
        duv, cuv = [], []
        for p in per_rec[i]:
            d = _field(p, "depth_uv")
            c = (_field(p, "cameras") or {}).get(cam)
            if d is not None and c is not None:
                duv.append(np.asarray(d, dtype=np.float64).reshape(2))
                cuv.append(np.asarray(c, dtype=np.float64).reshape(2))
        return (np.array(duv), np.array(cuv)) if duv else None

    return pairs


def _field(p: Any, name: str) -> Any:
    return p.get(name) if isinstance(p, dict) else getattr(p, name, None)


def _points_of(entry: Any) -> list[Any]:
    pts = entry.get("points", []) if isinstance(entry, dict) else getattr(entry, "points", entry)
    return list(pts or [])


def landmark_residuals(rig: Rig, recordings: Sequence[Recording], source: LandmarkSource,
                       camera: str) -> np.ndarray:
    """Distances (px, (N,)) between the landmarks' camera pixels and their depth pixels carried
    through the recording's object mesh into ``camera`` (the registration's code path);
    landmarks without a mesh hit are left out."""
    out = []
    for i, rec in enumerate(recordings):
        pr = source(i, camera)
        if pr is None or len(pr[0]) == 0:
            continue
        duv, cuv = pr
        uv = transport_pixels(rig, rec.depth_m(rig.depth_scale), rig.depth_camera, duv, camera)
        d = np.linalg.norm(uv - cuv, axis=1)
        out.append(d[np.isfinite(d)])
    return np.concatenate(out) if out else np.zeros(0)


# ---------------------------------------------------------------------------- images
def _single_channel(img: np.ndarray) -> np.ndarray:
    """(H, W) or (H, W, C) any dtype -> (H, W) float32: the first principal component of the
    channels (sign irrelevant for the NID), non-finite values replaced by the median."""
    a = np.asarray(img)
    if a.ndim == 3 and a.shape[2] == 1:
        a = a[:, :, 0]
    if a.ndim == 2:
        out = a.astype(np.float32)
    else:
        H, W, C = a.shape
        flat = a.reshape(H * W, C)
        rng = np.random.default_rng(0)
        sub = flat[rng.choice(H * W, size=min(H * W, 5000), replace=False)].astype(np.float64)
        sub = sub[np.isfinite(sub).all(axis=1)]
        if len(sub) < 10:
            out = np.nanmean(a.astype(np.float32), axis=2)
        else:
            mu = sub.mean(axis=0)
            evals, evecs = np.linalg.eigh(np.cov(sub - mu, rowvar=False))  # C x C: cheap for 200 bands
            w = evecs[:, -1].astype(np.float32)
            out = np.zeros((H, W), np.float32)
            for b0 in range(0, C, 16):  # band blocks: no float64 copy of a large cube
                blk = np.nan_to_num(a[:, :, b0:b0 + 16].astype(np.float32) - mu[b0:b0 + 16].astype(np.float32))
                out += np.tensordot(blk, w[b0:b0 + 16], axes=([2], [0]))
    bad = ~np.isfinite(out)
    if bad.any():
        out[bad] = np.median(out[~bad]) if (~bad).any() else 0.0
    return np.ascontiguousarray(out)


def _blur(img: np.ndarray, sigma: float) -> np.ndarray:
    if sigma < 0.3:
        return img
    return cv2.GaussianBlur(img, (0, 0), sigmaX=float(sigma), sigmaY=float(sigma), borderType=cv2.BORDER_REPLICATE)


def _bilinear(img: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Samples of ``img`` (h, w) float32 at ``uv`` (N, 2), clamped to the image, (N,) float32.
    Exact weights (``cv2.remap`` quantises them to 1/32 px, which would make the cost a staircase)."""
    h, w = img.shape
    u = np.clip(uv[:, 0], 0, w - 1.0001)  # NaN stays NaN and would index garbage: callers pass finite uv
    v = np.clip(uv[:, 1], 0, h - 1.0001)
    return _bilinear_uv(img, u, v)


def _bilinear_uv(img: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """:func:`_bilinear` for ``u``, ``v`` (N,) already inside [0, w - 1.0001] x [0, h - 1.0001]
    (exact weights, no clamping, fewer temporaries: the cost's hot path), (N,) float32."""
    w = img.shape[1]
    u0 = u.astype(np.int64)
    v0 = v.astype(np.int64)
    fu = (u - u0).astype(np.float32)
    fv = (v - v0).astype(np.float32)
    flat = img.ravel()
    i = v0 * w + u0
    a = flat[i]
    b = flat[i + 1]
    c = flat[i + w]
    d = flat[i + w + 1]
    top = a + fu * (b - a)
    bot = c + fu * (d - c)
    return top + fv * (bot - top)


def _increasing(edges: np.ndarray) -> np.ndarray:
    """Make quantile knots strictly increasing (constant images give repeated quantiles)."""
    e = np.asarray(edges, dtype=np.float64)
    span = max(float(e[-1] - e[0]), 1e-6)
    return e + np.arange(len(e)) * span * 1e-9 + np.arange(len(e)) * 1e-12


# ---------------------------------------------------------------------------- data per recording
@dataclass
class _RecData:
    """Camera-independent data of one recording: candidate points and the reference image."""

    X_rig: np.ndarray        # (M, 3) float32, usable depth pixels, random order
    pix: np.ndarray          # (M,) flat depth-pixel index of each point
    ref: np.ndarray          # (H, W) float32 reference image (infrared or depth)
    meshes: Meshes


@dataclass
class _Level:
    """All recordings at one level for one camera: fixed point sets and binning, concatenated
    so that one evaluation is a handful of numpy calls however many recordings there are."""

    XT: np.ndarray           # (3, n) float64 rig points of every recording, as rows (see _project_T)
    rec: np.ndarray          # (n,) int64 recording slot of each point (0 .. R-1)
    cell: np.ndarray         # (n,) int64 (rec * bins + reference bin) * bins: histogram row start
    voff: np.ndarray         # (n,) float64 row offset of the point's recording in ``atlas``
    atlas: np.ndarray        # (R * h, w) float32 blurred source images mapped to bin positions [0, bins - 1]
    h: int                   # height of one source image
    taper: float             # px: weight ramps from 0 at the image border to 1 this far inside
    weight: np.ndarray       # (n,) float64: object (ROI) and background points weigh the same per recording
    n_rec: int
    bins: int
    rec_index: list[int]     # slot -> index into the caller's recordings

    def __len__(self) -> int:
        return self.XT.shape[1]


def _prepare_recording(rig: Rig, rec: Recording, rays_cam: np.ndarray, p: RefineParams,
                       rng: np.random.Generator) -> _RecData:
    dcam = rig.depth()
    depth_raw = rec.depth_m(rig.depth_scale)
    rp = RegistrationParams(occlusion_tol_m=p.occlusion_tol_m)
    # the registration's ToF clean-up (flying pixels, same-surface denoising): points on the
    # surfaces the meshes are built from, so that a point does not hide behind its own surface
    depth, _flying = filter_depth(depth_raw, rp)
    H, W = depth.shape
    # mixed pixels: a large depth range in the 3x3 neighbourhood (or a neighbour without depth)
    big = np.where(np.isfinite(depth), depth, np.float32(np.inf))
    small = np.where(np.isfinite(depth), depth, np.float32(0))
    k = np.ones((3, 3), np.uint8)
    hi = cv2.dilate(small, k, borderType=cv2.BORDER_REPLICATE)
    lo = cv2.erode(big, k, borderType=cv2.BORDER_REPLICATE)
    with np.errstate(invalid="ignore"):
        ok = np.isfinite(depth) & ((hi - lo) <= np.maximum(p.depth_jump_m, 0.015 * depth))
    pix = np.flatnonzero(ok.ravel())
    pix = pix[rng.permutation(len(pix))][: p.candidates * p.max_points]
    X_cam = rays_cam[pix] * depth.ravel()[pix, None].astype(np.float64)
    X_rig = dcam.to_rig(X_cam).astype(np.float32)
    if rig.depth_camera in rec.images:
        ref = _single_channel(rec.images[rig.depth_camera])
    else:
        ref = np.nan_to_num(depth, nan=float(np.nanmax(depth)) if np.isfinite(depth).any() else 0.0)
    meshes = build_meshes(rig, depth_raw, rp, rays_cam=rays_cam)
    return _RecData(X_rig, pix, ref, meshes)


def _visible(cam: Camera, data: _RecData, idx: np.ndarray, tol: float, radius: float = 0.0) -> np.ndarray:
    """(len(idx),) bool: neither mesh lies on the segment from the source centre to the point
    (stopping ``tol`` before it): not P2 and not P3.2 -- from the camera centre and from the six
    centres ``radius`` metres away along the rig axes (visibility depends on the centre only).

    Why the union: visibility computed at the current estimate alone removes exactly the points
    that would show it wrong (ground points next to a leaf's silhouette that the wrong pose puts
    on the leaf), and the refinement then stays where it is (measured on the demo: thermal ended
    1.7 px off with the estimate's own visibility, at the truth with the truth's)."""
    ok = np.ones(len(idx), dtype=bool)
    offsets = [np.zeros(3)] + ([radius * s * e for e in np.eye(3) for s in (-1, 1)] if radius > 0 else [])
    for off in offsets:
        c = (cam.center_rig + off).astype(np.float32)
        vec = data.X_rig[idx] - c
        dist = np.sqrt(np.einsum("ij,ij->i", vec, vec))
        with np.errstate(divide="ignore", invalid="ignore"):
            scale = 1.0 - np.float32(tol) / dist
        usable = scale > 0
        vec = vec * np.where(usable, scale, 0)[:, None].astype(np.float32)
        sel = np.flatnonzero(ok & usable)
        ok &= usable
        occ = data.meshes.object_scene.occluded(c, vec[sel]) | data.meshes.uncertainty_scene.occluded(c, vec[sel])
        ok[sel[occ]] = False
    return ok


# ---------------------------------------------------------------------------- cost
def _project_T(cam: Camera, XT: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:meth:`Camera.project` of points stored as rows ``XT`` (3, N) float64 -> ``u``,
    ``v`` (N,) each, without its NaN marking (callers keep points in front of the camera).

    The cost's hot path: ``R @ XT`` is one small BLAS call, where ``X @ R.T`` with X (N, 3) was
    slow with OpenBLAS threads spinning on a loaded machine, this whole function is not. The
    lens model is the camera module's (:func:`~plantreg_gui.core.camera.camera.distort_normalized`)."""
    if _has_tilt(cam):
        uv = cam.project(XT.T)[0]
        return uv[:, 0], uv[:, 1]
    t = cam.t_cam_rig
    Xc = cam.R_cam_rig @ XT
    iz = 1.0 / np.maximum(Xc[2] + t[2], 1e-9)
    return distort_normalized(cam, (Xc[0] + t[0]) * iz, (Xc[1] + t[1]) * iz)


def _project_uvz(cam: Camera, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:meth:`Camera.project` (uv (N, 2), NaN behind the camera; z (N,)) through the
    fast path of :func:`_project_T`."""
    XT = np.ascontiguousarray(np.asarray(X, dtype=np.float64).T)
    z = cam.R_cam_rig[2] @ XT + cam.t_cam_rig[2]
    u, v = _project_T(cam, XT)
    uv = np.stack([u, v], axis=1)
    uv[~(z > 0)] = np.nan
    return uv, z


def _nid_per_recording(lv: _Level, cam: Camera, cell: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """NID (R,) of each recording slot and its total weight (R,) for camera ``cam``."""
    B = lv.bins
    u, v = _project_T(cam, lv.XT)
    w_img = lv.atlas.shape[1]
    # points count fully inside the image and fade out over ``lv.taper`` px towards its border:
    # the overlap changes smoothly, and points outside carry no (clamped, made-up) values
    with np.errstate(invalid="ignore"):
        inside = np.minimum(np.minimum(u + 0.5, w_img - 0.5 - u), np.minimum(v + 0.5, lv.h - 0.5 - v))
        wt = np.clip(inside * (1.0 / lv.taper), 0.0, 1.0)
        wt *= lv.weight
    np.clip(u, 0, w_img - 1.0001, out=u)
    np.clip(v, 0, lv.h - 1.0001, out=v)
    v += lv.voff
    q = _bilinear_uv(lv.atlas, u, v)  # the atlas holds bin positions (see _level_data)
    i0 = np.minimum(q.astype(np.int64), B - 2)
    fr = q - i0
    base = (lv.cell if cell is None else cell) + i0
    n_cells = lv.n_rec * B * B
    wf = wt * fr
    # one bincount for both soft-binning neighbours (the cell and the next source bin)
    h = np.bincount(np.concatenate([base, base + 1]), weights=np.concatenate([wt - wf, wf]),
                    minlength=n_cells).reshape(lv.n_rec, B, B)
    tot = h.sum(axis=(1, 2))
    P = h / np.maximum(tot, 1e-12)[:, None, None]

    def ent(x: np.ndarray) -> np.ndarray:  # entropy over all but the first axis
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.where(x > 0, x * np.log(x), 0.0)
        return -t.reshape(len(x), -1).sum(axis=1)

    hxy = ent(P)
    mi = ent(P.sum(axis=2)) + ent(P.sum(axis=1)) - hxy
    with np.errstate(divide="ignore", invalid="ignore"):
        nid = np.where(hxy > 0, 1.0 - mi / hxy, 1.0)
    return nid, tot


def _cost(lv: _Level, cam: Camera, p: RefineParams | None = None) -> tuple[float, list[float]]:
    """Weighted mean NID over the recordings (plus ``p.extra_cost``, if any), and the NID of each."""
    nid, tot = _nid_per_recording(lv, cam)
    c = float(np.dot(tot, nid) / tot.sum()) if tot.sum() > 0 else 1.0
    if p is not None and p.extra_cost is not None:
        c += float(p.extra_cost(cam))
    return c, [float(x) for x in nid]


# ---------------------------------------------------------------------------- parametrisation
class _Param:
    """Maps a parameter vector (in blur widths) to a camera near ``base``.

    p[0], p[1]: rotation moving the image by p * sigma px in y and x; p[2]: roll, p * sigma px at
    radius ``rho``; p[3], p[4]: x, y translation whose shift at the median depth ``zm`` is
    cancelled by rotation (p * sigma px of shift before that); p[5]: z translation (p * sigma px
    at radius ``rho`` and depth ``zm``; with a free focal length the focal compensates its scale
    at ``zm``); p[6] (focal free): focal length, p * sigma px at radius ``rho``.
    """

    def __init__(self, base: Camera, sigma_px: float, zm: float, focal: bool):
        self.base = base
        self.s = float(sigma_px)
        self.f = float(np.sqrt(base.K[0, 0] * base.K[1, 1]))
        self.rho = 0.35 * float(np.hypot(base.width, base.height))
        self.zm = float(zm)
        self.focal = focal
        self.n = 7 if focal else 6

    def camera(self, p: np.ndarray) -> Camera:
        s, f, rho, zm = self.s, self.f, self.rho, self.zm
        a = p[3] * s * zm / f
        b = p[4] * s * zm / f
        dz = p[5] * s * zm / rho
        omega = np.array([p[0] * s / f + b / zm, -p[1] * s / f - a / zm, p[2] * s / rho])
        dR = cv2.Rodrigues(omega)[0]
        cam = copy.copy(self.base)
        cam.R_cam_rig = dR @ self.base.R_cam_rig
        cam.t_cam_rig = dR @ self.base.t_cam_rig + np.array([a, b, dz])
        scale = 1.0
        if self.focal:
            scale = (zm + dz) / zm * (1.0 + p[6] * s / rho)
        if scale != 1.0:
            K = self.base.K.copy()
            K[0, 0] *= scale
            K[1, 1] *= scale
            cam.K = K
        return cam


# ---------------------------------------------------------------------------- the refinement
def refine_rig(rig: Rig, recordings: list[Recording], *, cameras: list[str] | None = None,
               free: frozenset[str] = frozenset(), landmarks: Any = None,
               progress: Reporter | None = None, params: RefineParams | None = None) -> RefineResult:
    """Refine the pose (and, with ``"focal" in free``, the focal length) of every camera in
    ``cameras`` (default: all but the depth camera) from ``recordings`` of this rig, jointly.

    ``landmarks``: optional, only to *check* the result (not used by the objective); anything
    :func:`landmark_source` accepts. ``free``: ``"focal"`` (every refined camera) or
    ``"CAMERA:focal"``, as the landmark fit takes them; other items are kept fixed with a warning
    (images constrain principal point and distortion poorly; the landmark fit frees them). Returns a :class:`RefineResult`; ``report["cameras"][name]`` holds ``start_cost``,
    ``end_cost`` (NID, 0 = perfect dependence, 1 = none), ``cost_per_recording`` (start, end),
    ``iterations`` (cost evaluations), ``converged``, ``kept`` (``"refined"`` or why the start pose
    was kept), ``information`` and ``contrast`` (the convergence tests), ``change``
    (``rotation_deg``, ``translation_mm``, ``focal_pct``), ``levels``, and with landmarks
    ``landmarks_px`` (median / p90 / n before and after). The refined rig carries the report
    (without ``params``) under ``extra["calibration"]["refine"]``.
    Raises :class:`InputError` for an unusable request (no depth camera, unknown camera, no recording).
    """
    p = params or RefineParams()
    progress = ensure_reporter(progress)
    t_start = time.perf_counter()
    cpu_start = time.process_time()
    dcam = rig.depth()
    if not recordings:
        raise InputError("refinement needs at least one recording")
    names = [c.name for c in rig.cameras if c.name != dcam.name] if cameras is None else list(cameras)
    for n in names:
        rig.camera(n)  # InputError if unknown
        if n == dcam.name:
            raise InputError(f"camera '{n}' is the depth camera: its pose defines the rig frame and is not refined")
    warnings: list[str] = []
    # ``free`` items as the landmark fit takes them: "focal" (every camera) or "CAMERA:focal"
    kept = sorted({it for it in free if it.split(":", 1)[-1] not in REFINABLE
                   and (":" not in it or it.split(":", 1)[0] in names)})
    if kept:
        warnings.append(f"refinement keeps {', '.join(kept)} fixed (images refine only the pose and the focal length)")

    def focal_free(name: str) -> bool:
        return any(f in free for f in ("focal", f"{name}:focal"))

    for rec in recordings:
        rec.check(rig)
    out_rig = copy.deepcopy(rig)
    lm = landmark_source(landmarks, recordings)

    rng = np.random.default_rng(p.seed)
    with progress.stage("preparing recordings", 0.0, 0.1):
        rays_cam = pixel_rays_cam(dcam)
        data = []
        for i, rec in enumerate(recordings):
            progress(0.1 * i / len(recordings), "preparing recordings")
            data.append(_prepare_recording(rig, rec, rays_cam, p, rng))

    report: dict[str, Any] = {"method": "NID of depth-camera image vs source image over depth points",
                              "free": sorted(free), "recordings": len(recordings),
                              "params": {k: (list(v) if isinstance(v, tuple) else v) for k, v in vars(p).items()},
                              "cameras": {}}
    todo = [n for n in names if any(n in r.images for r in recordings)]
    for n in names:
        if n not in todo:
            warnings.append(f"{n}: no recording has an image of this camera; not refined")
    # cameras are independent given the recordings' data: refine them concurrently, with one
    # progress value (the mean over the cameras) so that the bar does not jump between them
    fractions = [0.0] * len(todo)
    lock = threading.Lock()
    stop = _EitherToken(progress.cancel)  # the caller's cancel, or one camera failed

    def camera_reporter(ci: int) -> Reporter:
        def report_fraction(f: float, message: str) -> None:
            with lock:  # reported under the lock: the values arrive in order (never backwards)
                fractions[ci] = max(fractions[ci], f)
                progress(0.1 + 0.9 * sum(fractions) / len(fractions), message)

        return Reporter(report_fraction, stop)

    def run(ci: int, name: str) -> tuple[dict[str, Any], Camera, list[str]]:
        return _refine_camera(rig, out_rig.camera(name), dcam, recordings, data, p, focal_free(name),
                              camera_reporter(ci))

    n_workers = max(1, min(int(p.workers), len(todo)))
    if n_workers == 1:
        results = [run(ci, name) for ci, name in enumerate(todo)]
    else:
        with ThreadPoolExecutor(n_workers, thread_name_prefix="refine") as pool:
            futures = [pool.submit(run, ci, name) for ci, name in enumerate(todo)]
            try:
                results = [f.result() for f in futures]
            except BaseException:
                stop.cancel()  # stop the other cameras at their next cancellation point
                raise
    for ci, name in enumerate(todo):
        cam0 = out_rig.camera(name)
        entry, cam_new, warn = results[ci]
        entry["focal_free"] = focal_free(name)
        if lm is not None:
            before = landmark_residuals(rig, recordings, lm, name)
            tmp = copy.deepcopy(out_rig)
            _replace(tmp, cam_new)
            after = landmark_residuals(tmp, recordings, lm, name)
            entry["landmarks_px"] = {"before": _stats(before), "after": _stats(after)}
            if len(after) and np.median(after) > p.landmark_warn_px:
                worse = len(before) > 0 and np.median(after) > np.median(before)
                if worse and p.keep_if_landmarks_disagree:
                    # hand-read landmarks (1-4 px) outrank a similarity that moved away from them
                    cam_new = cam0
                    entry["kept"] = "start (landmarks disagree)"
                warn.append(f"{name}: refined pose disagrees with the landmarks by {np.median(after):.1f} px median "
                            f"({len(after)} landmarks; {np.median(before):.1f} px before)"
                            + ("; the start pose is kept" if entry.get("kept") == "start (landmarks disagree)" else ""))
        _replace(out_rig, cam_new)
        report["cameras"][name] = entry
        warnings.extend(warn)
    report["seconds"] = round(time.perf_counter() - t_start, 2)
    report["cpu_seconds"] = round(time.process_time() - cpu_start, 2)  # all threads of this process
    calib = dict(out_rig.extra.get("calibration", {})) if isinstance(out_rig.extra.get("calibration"), dict) else {}
    calib["refine"] = {k: v for k, v in report.items() if k != "params"}
    out_rig.extra["calibration"] = calib
    progress(1.0, "refinement done")
    return RefineResult(out_rig, report, warnings)


class _EitherToken(CancelToken):
    """Cancelled when the caller's token is, or when :meth:`cancel` is called on this one (which
    leaves the caller's token alone)."""

    def __init__(self, outer: CancelToken):
        super().__init__()
        self.outer = outer

    @property
    def cancelled(self) -> bool:
        return self._event.is_set() or self.outer.cancelled

    def raise_if_cancelled(self) -> None:
        self.outer.raise_if_cancelled()
        super().raise_if_cancelled()


def _replace(rig: Rig, cam: Camera) -> None:
    rig.cameras = [cam if c.name == cam.name else c for c in rig.cameras]


def _stats(d: np.ndarray) -> dict[str, Any]:
    if len(d) == 0:
        return {"n": 0}
    return {"n": int(len(d)), "median": round(float(np.median(d)), 3), "p90": round(float(np.percentile(d, 90)), 3)}


def _refine_camera(rig: Rig, cam0: Camera, dcam: Camera, recordings: Sequence[Recording], data: Sequence[_RecData],
                   p: RefineParams, focal: bool, progress: Reporter) -> tuple[dict[str, Any], Camera, list[str]]:
    from scipy.optimize import minimize

    name = cam0.name
    roi = (rig.roi_min, rig.roi_max)
    f_src = float(np.sqrt(cam0.K[0, 0] * cam0.K[1, 1]))
    f_ref = float(np.sqrt(dcam.K[0, 0] * dcam.K[1, 1]))
    src_imgs = {i: _single_channel(r.images[name]) for i, r in enumerate(recordings) if name in r.images}
    cam = cam0
    evals = 0
    levels_out = []
    warn: list[str] = []
    lv: _Level | None = None
    with progress.stage(f"{name}: visibility"), _RAYCAST_LOCK:
        # computed once at the start pose, for the union of centres within visibility_radius_m
        # (ray casting only for candidates within twice the coarsest level's reach of the image:
        # the others are never used, and casting them was a third of the setup time)
        reach0 = 2.0 * p.bound_units * max(p.min_sigma_px, f_src * np.radians(max(p.levels_deg)))
        visible = {}
        for i, d in enumerate(data):
            if i not in src_imgs:
                continue
            cand = np.arange(min(len(d.X_rig), p.candidates * p.max_points))
            uv, z = _project_uvz(cam0, d.X_rig[cand])
            near = cam0.in_image(uv, -reach0) & (z > 0)
            vis = np.zeros(len(d.X_rig), bool)
            vis[cand[near]] = _visible(cam0, d, cand[near], p.occlusion_tol_m, p.visibility_radius_m)
            visible[i] = vis
    res = None
    par = None
    for li, deg in enumerate(p.levels_deg):
        progress(li / len(p.levels_deg), f"{name}: level {li + 1}/{len(p.levels_deg)}")
        ang = np.radians(deg)
        sig_src = max(p.min_sigma_px, f_src * ang)
        sig_ref = max(0.0, f_ref * ang)
        lv, zs = _level_data(cam, dcam, data, src_imgs, sig_src, sig_ref, p, p.bound_units * sig_src, roi, visible)
        if lv is None:
            warn.append(f"{name}: no depth point is visible in this camera at the start pose; not refined")
            return {"converged": False, "reason": "no visible depth points"}, cam0, warn
        par = _Param(cam, sig_src, float(np.median(zs)), focal)
        active = (p.active_params or _active_params)(li, len(p.levels_deg), focal)
        b = p.bound_units
        lim = np.full(par.n, b)
        # translation and focal per level at most ``max_translation_m`` / ``max_focal`` from here
        lim[[3, 4]] = p.max_translation_m * par.f / (sig_src * par.zm)
        lim[5] = p.max_translation_m * par.rho / (sig_src * par.zm)
        if focal:
            lim[6] = p.max_focal * par.rho / sig_src

        def full(x: np.ndarray) -> np.ndarray:
            v = np.zeros(par.n)
            v[active] = x
            return v

        fun = _counted(lambda x, lv=lv, par=par: _cost(lv, par.camera(full(x)), p)[0], progress)
        c0 = fun(np.zeros(len(active)))
        last = li == len(p.levels_deg) - 1
        bounds = [(-lim[k], lim[k]) for k in active]
        opts = {"xtol": p.xtol if last else 5 * p.xtol, "ftol": 1e-6, "maxfev": p.maxfev_per_param * len(active)}
        # Powell (derivative-free: finite-difference gradients of this cost were measured too noisy
        # for L-BFGS at the finest level). When it runs out of evaluations, restart it from where it
        # stopped (a fresh direction set); a restart that no longer moves counts as converged.
        res = minimize(fun, np.zeros(len(active)), method="Powell", bounds=bounds, options=opts)
        for _ in range(p.restarts):
            if res.success:
                break
            again = minimize(fun, res.x, method="Powell", bounds=bounds, options=opts)
            moved = float(np.max(np.abs(again.x - res.x)))
            again.success = bool(again.success or moved < 0.1)
            res = again
        evals += fun.n
        on_bound = bool(np.any(np.abs(res.x) > 0.98 * lim[active]))
        res.x = full(res.x)
        cam = par.camera(res.x)
        levels_out.append({"blur_deg": deg, "sigma_px": round(sig_src, 2), "points": len(lv),
                           "start_cost": round(c0, 5), "end_cost": round(float(res.fun), 5),
                           "step_px": round(float(np.max(np.abs(res.x))) * sig_src, 3), "evaluations": fun.n,
                           "success": bool(res.success)})
    assert res is not None and par is not None
    # convergence tests on the finest level's point set
    assert lv is not None
    end_cost, end_per = _cost(lv, cam, p)
    start_cost, start_per = _cost(lv, cam0, p)
    rng = np.random.default_rng(p.seed + 1)
    shuffled = lv.cell.copy()
    for r in range(lv.n_rec):  # reference bins shuffled within each recording: the NID of chance
        sel = np.flatnonzero(lv.rec == r)
        shuffled[sel] = lv.cell[rng.permutation(sel)]
    nid_c, tot_c = _nid_per_recording(lv, cam, shuffled)
    chance_cost = float(np.dot(tot_c, nid_c) / tot_c.sum())
    information = chance_cost - end_cost
    # the probe scales with the image (a smooth thermal image changes little over 3 px)
    probe_px = max(p.probe_px, p.probe_frac * float(np.hypot(cam.width, cam.height)))
    probe = _Param(cam, probe_px, par.zm, False)
    shifted = [_cost(lv, probe.camera(np.eye(6)[k] * sgn), p)[0] for k in (0, 1) for sgn in (-1, 1)]
    contrast = (min(shifted) - end_cost) / max(information, 1e-3)
    converged = bool(res.success) and not on_bound and information >= p.min_information and contrast >= p.min_contrast
    if not converged:
        why = []
        if not res.success:
            why.append("optimiser stopped before convergence")
        if on_bound:
            why.append("the result lies on the search bound")
        if information < p.min_information:
            why.append(f"the images share almost no information (NID {end_cost:.3f} vs chance {chance_cost:.3f})")
        elif contrast < p.min_contrast:
            why.append(f"the cost has no clear minimum (moving {probe_px:.0f} px changes it by only "
                       f"{contrast * 100:.0f} % of the information)")
        warn.append(f"{name}: did not converge ({'; '.join(why)}); keep the start pose or check the images")
    dR = cam.R_cam_rig @ cam0.R_cam_rig.T
    change = {
        "rotation_deg": round(float(np.degrees(np.linalg.norm(cv2.Rodrigues(dR)[0]))), 4),
        "translation_mm": round(float(np.linalg.norm(cam.center_rig - cam0.center_rig) * 1000), 2),
        "focal_pct": round(float((cam.K[0, 0] / cam0.K[0, 0] - 1) * 100), 3),
    }
    entry = {
        "start_cost": round(start_cost, 5), "end_cost": round(end_cost, 5), "chance_cost": round(chance_cost, 5),
        "information": round(information, 5), "contrast": round(float(contrast), 4),
        "cost_per_recording": {str(lv.rec_index[k]): {"start": round(a, 5), "end": round(b_, 5)}
                               for k, (a, b_) in enumerate(zip(start_per, end_per))},
        "iterations": evals, "converged": converged, "change": change, "levels": levels_out,
    }
    entry["kept"] = "refined" if converged else "start"
    # a camera that did not converge keeps its start pose: an unconstrained optimum is no estimate
    return entry, (cam if converged else cam0), warn


def _active_params(level: int, n_levels: int, focal: bool) -> list[int]:
    """Parameters searched at ``level``: rotation only while the blur is coarse (measured on the
    demo: with blurred images the optimum of translation and focal length lies several blur
    widths from the truth, that of rotation within a quarter), the focal length from the third
    level from the end, x/y translation on the last two, z translation (whose optimum is the
    most biased by blur) on the last only."""
    act = [0, 1, 2]
    if focal and level >= n_levels - 3:
        act.append(6)
    if level >= n_levels - 2:
        act += [3, 4]
    if level == n_levels - 1:
        act.append(5)
    return sorted(act)


class _counted:
    """Cost function wrapper counting evaluations; a cancellation point every 20 calls."""

    def __init__(self, f: Callable[[np.ndarray], float], progress: Reporter):
        self.f = f
        self.n = 0
        self.progress = progress

    def __call__(self, x: np.ndarray) -> float:
        self.n += 1
        if self.n % 20 == 0:
            self.progress.check()
        return self.f(x)


def _level_data(cam: Camera, dcam: Camera, data: Sequence[_RecData], src_imgs: dict[int, np.ndarray],
                sig_src: float, sig_ref: float, p: RefineParams, reach_px: float,
                roi: tuple[np.ndarray, np.ndarray], visible: dict[int, np.ndarray]) -> tuple[_Level | None, np.ndarray]:
    """Fixed point sets and binning of one level at the level's start pose; ``visible[i]`` (M_i,)
    bool marks the recording's candidate points the source sees (see :func:`_visible`)."""
    taper = 2.0 * sig_src + 1.0
    margin = -reach_px  # points that may come into view during this level are kept (with weight 0 outside)
    area = dcam.width * dcam.height
    n_want = int(np.clip(area / max(0.5 * sig_ref, 1.0) ** 2, p.min_points, p.max_points))
    nb = p.bins
    parts: dict[str, list[np.ndarray]] = {k: [] for k in ("X", "rec", "cell", "voff", "weight", "z")}
    atlas, slots = [], []
    for i, d in enumerate(data):
        if i not in src_imgs:
            continue
        cand = np.flatnonzero(visible[i])
        uv, z = _project_uvz(cam, d.X_rig[cand])
        idx = cand[cam.in_image(uv, margin) & (z > 0)][:n_want]
        if len(idx) < 200:
            continue
        idx = idx[np.argsort(d.pix[idx], kind="stable")]  # raster order: neighbours sample nearby source pixels
        uv, z = _project_uvz(cam, d.X_rig[idx])
        slot = len(slots)
        blur = p.image_filter or _blur
        img = blur(src_imgs[i], sig_src)
        ref = blur(d.ref, sig_ref).ravel()[d.pix[idx]]
        redges = np.unique(np.quantile(ref, np.linspace(0, 1, nb + 1)[1:-1]))
        ref_bin = np.searchsorted(redges, ref, side="right").astype(np.int64)
        seen = uv[cam.in_image(uv)]
        s = _bilinear(img, seen if len(seen) >= 100 else uv)
        knots = _increasing(np.quantile(s, np.linspace(0, 1, nb + 1)))
        # map the image to continuous bin positions once (equal-population bins of the values the
        # points see), instead of mapping every sample in every evaluation
        atlas.append(np.interp(img, knots, np.linspace(0, nb - 1, nb + 1)).astype(np.float32))
        X = d.X_rig[idx].astype(np.float64)
        obj = np.all((X >= roi[0]) & (X <= roi[1]), axis=1)
        weight = np.ones(len(X))
        if 0 < obj.sum() < len(X):  # the plant is usually a small part of the view: do not let the ground outvote it
            weight[obj] = 0.5 * len(X) / obj.sum()
            weight[~obj] = 0.5 * len(X) / (~obj).sum()
        parts["X"].append(X)
        parts["rec"].append(np.full(len(X), slot))
        parts["cell"].append((slot * nb + ref_bin) * nb)
        parts["voff"].append(np.full(len(X), float(slot * cam.height)))
        parts["weight"].append(weight)
        parts["z"].append(z)
        slots.append(i)
    if not slots:
        return None, np.zeros(0)
    cat = {k: np.concatenate(v) for k, v in parts.items()}
    weight = cat["weight"] if p.point_weights is None else p.point_weights(cat["X"], roi, cat["weight"])
    lv = _Level(np.ascontiguousarray(cat["X"].T), cat["rec"], cat["cell"], cat["voff"], np.ascontiguousarray(np.concatenate(atlas, axis=0)),
                cam.height, taper, weight, len(slots), nb, slots)
    return lv, cat["z"]
