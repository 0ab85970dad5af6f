"""Fit a rig from landmarks: depth-camera pixels and the same points clicked in other cameras.

Model (see docs/fit-rig.md):

* A landmark's 3D point is ``z * (x, y, 1)`` in the depth camera's frame, where ``z`` is read from
  the depth map around the clicked pixel -- robustly, from the surface under the click (see
  :func:`landmark_depth`), never from one flying pixel -- and ``(x, y)`` is the clicked pixel
  undistorted with the depth camera's *current* intrinsics (so freeing them moves the points).
* Every other camera with landmarks gets a pose (rotation, optical centre in the rig frame) and,
  where asked (``free``), a focal scale (fx, fy together), principal point and first radial term
  ``k1``; the depth camera can get the same intrinsics (its pose defines the rig frame).
* All recordings are fitted jointly by ``scipy.optimize.least_squares`` with a robust loss
  (soft L1) on the pixel residuals and weak Gaussian priors pulling every parameter towards the
  start rig (:class:`Priors`): with a plant spanning little depth, focal length and distance
  trade off, and the priors keep such directions where the start rig put them.
* Start poses come from the start rig, or from ``cv2.solvePnPRansac`` where the start rig
  explains the landmarks badly (a rough placement). Landmarks far off after the robust fit are
  flagged as outliers and the fit is repeated without them.

Length: one least-squares problem (parameters, priors, residuals, robust loss, leave-one-out) and
its reporting; the landmark file format lives in :mod:`..data.landmarks`.
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, field
from typing import Any, Iterable, Sequence

import cv2
import numpy as np
from scipy.optimize import least_squares
from scipy.sparse import lil_matrix

from ..camera.camera import Camera
from ..errors import InputError
from ..data.landmarks import Landmark, LandmarkSet
from ..camera.rig import Rig

#: intrinsic parameters a fit may free, in parameter order and their vector sizes
FREE_ITEMS = {"focal": 1, "principal": 2, "k1": 1}

_UNDIST = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-12)


# ---------------------------------------------------------------------- nominal cameras
def nominal_camera(name: str, modality: str, width: int, height: int, hfov_deg: float, vfov_deg: float | None = None,
                   R_cam_rig: np.ndarray | None = None, t_cam_rig: np.ndarray | None = None,
                   dist: Iterable[float] | None = None, extra: dict[str, Any] | None = None) -> Camera:
    """A pinhole camera from a datasheet: ``fx = (w/2) / tan(hfov/2)``, ``fy = (h/2) / tan(vfov/2)``
    (``fy = fx`` without ``vfov_deg``), principal point at the image centre ((w-1)/2, (h-1)/2 with
    pixel centres at integers), no distortion unless ``dist`` is given."""
    if not (0 < hfov_deg < 180) or (vfov_deg is not None and not 0 < vfov_deg < 180):
        raise InputError(f"camera '{name}': field of view must be between 0 and 180 degrees")
    if width <= 0 or height <= 0:
        raise InputError(f"camera '{name}': width and height must be positive")
    fx = (width / 2.0) / math.tan(math.radians(hfov_deg) / 2.0)
    fy = fx if vfov_deg is None else (height / 2.0) / math.tan(math.radians(vfov_deg) / 2.0)
    K = np.array([[fx, 0, (width - 1) / 2.0], [0, fy, (height - 1) / 2.0], [0, 0, 1.0]])
    return Camera(name, modality, width, height, K, np.zeros(5) if dist is None else np.asarray(list(dist), float),
                  np.eye(3) if R_cam_rig is None else R_cam_rig, np.zeros(3) if t_cam_rig is None else t_cam_rig,
                  dict(extra or {}))


# ---------------------------------------------------------------------- options and data
@dataclass
class Priors:
    """Standard deviations of the Gaussian priors around the start rig (weak on purpose: they
    settle directions the landmarks do not determine, not the ones they do).

    ``click_px`` is the assumed click uncertainty that pixel residuals are divided by;
    ``robust_px`` is where the soft-L1 loss turns from quadratic to linear."""

    rotation_deg: float = 5.0
    position_m: float = 0.05
    focal_rel: float = 0.05
    principal_rel: float = 0.03  # of the image width
    k1: float = 0.2
    click_px: float = 1.0
    robust_px: float = 3.0


#: ``--prior`` keys -> :class:`Priors` fields
PRIOR_KEYS = {"rotation": "rotation_deg", "position": "position_m", "focal": "focal_rel",
              "principal": "principal_rel", "k1": "k1", "click": "click_px", "robust": "robust_px"}


def parse_priors(spec: str | None, base: Priors | None = None) -> Priors:
    """``"focal=0.2,rotation=10"`` -> :class:`Priors` (the others as ``base`` or the defaults).
    Keys: rotation (degrees), position (m), focal (relative), principal (of the image width), k1,
    click (px), robust (px)."""
    pr = Priors(**asdict(base)) if base is not None else Priors()
    for it in (spec or "").split(","):
        if not it.strip():
            continue
        k, eq, v = it.partition("=")
        k = k.strip()
        if not eq or k not in PRIOR_KEYS:
            raise InputError(f"--prior takes KEY=VALUE with KEY one of {', '.join(PRIOR_KEYS)}, got '{it.strip()}'")
        try:
            val = float(v)
        except ValueError:
            raise InputError(f"--prior {k}: '{v}' is not a number") from None
        if not (val > 0 and math.isfinite(val)):
            raise InputError(f"--prior {k}: must be a positive number, got '{v}'")
        setattr(pr, PRIOR_KEYS[k], val)
    return pr


@dataclass
class RecordingLandmarks:
    """One recording's landmarks: ``depth_m`` (H, W) metres along the depth camera's axis
    (NaN or <= 0 = none) and the clicked points."""

    name: str
    depth_m: np.ndarray
    points: list[Landmark]
    #: put a landmark whose depth lies behind the surface beside it onto that surface
    #: (:func:`depth_jump`; a click just past a leaf's edge reads the ground) -- else leave it out
    snap_depth: bool = True
    #: the caller's :func:`check_landmark_depth` of ``points`` by index (same ``snap_depth``), to
    #: spare reading them again (the landmark page repaints on every drag step); None = read here
    depth_checks: dict[int, "DepthCheck"] | None = None


@dataclass
class FitResult:
    """``rig`` the fitted rig; ``report`` JSON-able (see docs/fit-rig.md); ``warnings`` for the user."""

    rig: Rig
    report: dict[str, Any]
    warnings: list[str] = field(default_factory=list)


def parse_free(spec: str | Iterable[str] | None) -> frozenset[str]:
    """``"focal,principal,k1"`` or ``"thermal:focal,ir:k1"`` -> frozenset of items; an item without
    ``CAMERA:`` applies to every camera, the depth camera included."""
    if spec is None:
        return frozenset()
    items = [s.strip() for s in (spec.split(",") if isinstance(spec, str) else spec)]
    out = set()
    for it in items:
        if not it:
            continue
        what = it.split(":", 1)[-1]
        if what not in FREE_ITEMS:
            raise InputError(f"cannot free '{it}': choose from {', '.join(FREE_ITEMS)} "
                             f"(optionally as CAMERA:{'|'.join(FREE_ITEMS)})")
        out.add(it)
    return frozenset(out)


def _free_for(free: frozenset[str], name: str) -> list[str]:
    return [k for k in FREE_ITEMS if k in free or f"{name}:{k}" in free]


# ---------------------------------------------------------------------- robust depth under a click
def grow_surface(win: np.ndarray, ok: np.ndarray, seed: tuple[int, int]) -> np.ndarray:
    """(h, w) bool: the surface of the depth window ``win`` (h, w) metres grown from ``seed``
    (row, col) through the pixels ``ok`` (h, w) bool, 4-connected, by depth steps below 4 mm +
    0.5 % of the depth (the step of a leaf seen at 70 degrees; a jump to a leaf behind, the
    ground or a flying pixel is larger)."""
    reg = np.zeros_like(ok)
    reg[seed] = True
    stack = [seed]
    while stack:
        i, j = stack.pop()
        zi = win[i, j]
        for di, dj in ((1, 0), (-1, 0), (0, 1), (0, -1)):
            k, m = i + di, j + dj
            if (0 <= k < win.shape[0] and 0 <= m < win.shape[1] and ok[k, m] and not reg[k, m]
                    and abs(win[k, m] - zi) < 0.004 + 0.005 * zi):
                reg[k, m] = True
                stack.append((k, m))
    return reg


def inverse_depth_plane(z: np.ndarray, du: np.ndarray, dv: np.ndarray, w: np.ndarray) -> float:
    """Depth at the click of a least-squares plane in inverse depth (a plane's inverse depth is
    affine in the image) through pixels at offsets ``(du, dv)`` (N,) from the click with depths
    ``z`` (N,) and weights ``w`` (N,), refitted once without its worst pixels; nan if ill-posed."""
    A = np.stack([np.ones(z.size), du, dv], axis=1)
    keep = np.ones(z.size, bool)
    zc = math.nan
    for _ in range(2):
        if keep.sum() < 3 or np.linalg.matrix_rank(A[keep]) < 3:
            break
        sw = np.sqrt(w[keep])
        coef, *_ = np.linalg.lstsq(A[keep] * sw[:, None], (1.0 / z[keep]) * sw, rcond=None)
        if not coef[0] > 0:
            break
        zc = 1.0 / coef[0]
        res = np.abs(1.0 / (A @ coef) - z)
        keep = res <= max(0.002, 3.0 * float(np.median(res)))
    return zc


def landmark_depth(depth_m: np.ndarray, uv: np.ndarray, radius: int = 3, min_support: int = 5
                   ) -> tuple[float, str]:
    """Depth (metres along the optical axis) of the surface under the clicked pixel ``uv`` (2,).

    In the (2r+1)^2 window around the nearest pixel, grows the surface under the click: pixels
    4-connected to it whose depth steps by less than 4 mm + 0.5 % of the depth from a neighbour
    (the step of a leaf seen at 70 degrees; a jump to a leaf behind, the ground or a flying pixel
    is larger). A surface of fewer than ``min_support`` pixels is a flying pixel or a
    sliver: then the largest surface among the 3x3 core is used, else the click has no depth.
    On the surface, a least-squares plane in inverse depth (a plane's inverse depth is affine
    in the image), refitted once without its worst pixels and weighted towards the click, is
    evaluated at ``uv``: the sub-pixel click is kept and the value is not biased where an edge
    cuts the window.

    Returns ``(z, "")`` or ``(nan, reason)``.
    """
    H, W = depth_m.shape
    u0, v0 = int(round(float(uv[0]))), int(round(float(uv[1])))
    if not (0 <= u0 < W and 0 <= v0 < H):
        return math.nan, "outside the depth image"
    a0, a1, b0, b1 = max(0, v0 - radius), min(H, v0 + radius + 1), max(0, u0 - radius), min(W, u0 + radius + 1)
    win = np.asarray(depth_m[a0:a1, b0:b1], dtype=np.float64)
    ok = np.isfinite(win) & (win > 0)
    if ok.sum() < min_support:
        return math.nan, (f"no depth at or around the pixel (only {int(ok.sum())} of {win.size} pixels in the "
                          f"{2 * radius + 1}x{2 * radius + 1} window have depth)")
    cv, cu = v0 - a0, u0 - b0

    def grow(seed: tuple[int, int]) -> np.ndarray:
        return grow_surface(win, ok, seed)

    region = grow((cv, cu)) if ok[cv, cu] else np.zeros_like(ok)
    if region.sum() < min_support:
        best = region
        for i in range(max(0, cv - 1), min(win.shape[0], cv + 2)):
            for j in range(max(0, cu - 1), min(win.shape[1], cu + 2)):
                if ok[i, j] and not best[i, j]:
                    r = grow((i, j))
                    if r.sum() > best.sum():
                        best = r
        region = best
        if region.sum() < min_support:
            return math.nan, "only scattered (flying) depth pixels around the pixel, no surface under it"
    vv, uu = np.nonzero(region)
    z = win[region]
    du, dv = uu + b0 - uv[0], vv + a0 - uv[1]
    zc = inverse_depth_plane(z, du, dv, np.exp(-(du ** 2 + dv ** 2) / (2.0 * (0.6 * radius) ** 2)))
    if np.isfinite(zc) and z.min() - 0.005 <= zc <= z.max() + 0.005:
        return float(zc), ""
    return float(np.median(z)), ""


def depth_jump(depth_m: np.ndarray, uv: np.ndarray, z: float, ground_z: float | None = None, radius: int = 8
               ) -> tuple[str, float]:
    """Whether the depth ``z`` read under the click ``uv`` (2,) lies on a surface well behind one
    right beside it (the ground or a leaf behind, seen through a notch or just past a leaf's
    edge): two thirds of the pixels with depth in the (2r+1)^2 window lie more than 5 cm + 5 %
    nearer, or, for a depth within 5 cm of the ground plane ``ground_z``, a quarter of those in
    the 7x7 core or one within :data:`EDGE_REACH_PX` of the click. Returns ``("", nan)`` or
    ``(reason, z_snapped)``: the depth at the click of the nearer surface nearest to it (a plane
    in inverse depth through its pixels, weighted towards the click)."""
    H, W = depth_m.shape
    u0, v0 = int(round(float(uv[0]))), int(round(float(uv[1])))
    a0, a1, b0, b1 = max(0, v0 - radius), min(H, v0 + radius + 1), max(0, u0 - radius), min(W, u0 + radius + 1)
    win = np.asarray(depth_m[a0:a1, b0:b1], dtype=np.float64)
    ok = np.isfinite(win) & (win > 0)
    if ok.sum() < 10 or not np.isfinite(z):
        return "", math.nan
    near = ok & (win < z - (0.05 + 0.05 * z))
    cv, cu = v0 - a0, u0 - b0
    core_ok, core_near = (m[max(0, cv - 3):cv + 4, max(0, cu - 3):cu + 4] for m in (ok, near))
    at_ground = ground_z is not None and z > ground_z - 0.05
    d_near = _nearest(near, cv, cu)
    # surrounded by a nearer surface (a notch, a hole); or at the ground's depth right beside one
    # (a click on a leaf's corner or tip that the ToF's valid depth stops short of; a lower leaf
    # beside an upper one's edge is a fair landmark)
    beside = at_ground and (core_ok.sum() and core_near.sum() >= 0.25 * core_ok.sum() or d_near <= EDGE_REACH_PX)
    if near.sum() < 0.65 * ok.sum() and not beside:
        return "", math.nan
    # the nearer surface nearest the click (one leaf's corner, not a mix of the leaves around it)
    vn, un = np.nonzero(near)
    j = int(np.argmin(np.hypot(vn - cv, un - cu)))
    sel = grow_surface(win, near, (int(vn[j]), int(un[j])))
    if sel.sum() < 5:  # a sliver: the main nearer surface instead
        sel = near & (np.abs(win - np.median(win[near])) < 0.03 + 0.03 * np.median(win[near]))
    lead, zs = _plane_at_click(win, sel, uv, a0, b0, 0.5 * radius)
    where = " (the ground's depth)" if at_ground else ""
    return (f"depth {z:.3f} m{where} lies {100 * (z - lead):.0f} cm behind the surface "
            f"({lead:.3f} m) reaching to within {d_near:.0f} px of it and filling "
            f"{100 * near.sum() / ok.sum():.0f} % of its {2 * radius + 1}x{2 * radius + 1} neighbourhood: a click "
            "past a leaf's edge or through a notch"), float(zs)


def _plane_at_click(win: np.ndarray, sel: np.ndarray, uv: np.ndarray, a0: int, b0: int, sigma_px: float
                    ) -> tuple[float, float]:
    """(median depth, depth at the click ``uv``) of the surface ``sel`` (h, w) bool of the depth
    window ``win`` (h, w) whose top-left pixel is (row ``a0``, column ``b0``): a plane in inverse
    depth through its pixels weighted towards the click (Gaussian, ``sigma_px``), kept within 2 cm
    of the surface's depths (else the median)."""
    vv, uu = np.nonzero(sel)
    zn = win[sel]
    lead = float(np.median(zn))
    du, dv = uu + b0 - uv[0], vv + a0 - uv[1]
    zs = inverse_depth_plane(zn, du, dv, np.exp(-(du ** 2 + dv ** 2) / (2.0 * sigma_px ** 2)))
    if not (np.isfinite(zs) and zn.min() - 0.02 <= zs <= zn.max() + 0.02):
        zs = lead
    return lead, float(zs)


#: how far (px) beside a click that reads the ground a leaf's valid depth may end and the click
#: still count as on that leaf: the Azure Kinect's valid depth ends 2-4 px (thin tips up to 6.5 px)
#: short of the leaf's edge in its infrared image (resources/plant3dimagereg/README.md, "Raw clicks"
#: and "How the landmarks were made", step 3)
EDGE_REACH_PX = 7.0


@dataclass(frozen=True)
class DepthCheck:
    """What a landmark's depth pixel gives the fit (:func:`check_landmark_depth`).

    ``status``: ``"ok"`` (the surface under the click), ``"snapped"`` (the click read a surface
    behind the one beside it and was put onto the nearer one), ``"left out"`` (the same, with
    snapping off) or ``"no depth"``. ``read_m``: the depth read under the click (nan without
    one); ``z_m``: the depth the fit uses (nan when left out or none); ``reason``: why, for
    anything but ``"ok"``."""

    status: str
    z_m: float
    read_m: float
    reason: str = ""
    #: the nearer surface's depth at the click where the depth jumps (nan otherwise)
    snap_m: float = math.nan

    @property
    def used(self) -> bool:
        return math.isfinite(self.z_m)

    def snapping(self, snap: bool) -> "DepthCheck":
        """This check with snapping on or off (a jump is snapped or left out; others unchanged)."""
        if self.status not in ("snapped", "left out") or (self.status == "snapped") == snap:
            return self
        if snap:
            return DepthCheck("snapped", self.snap_m, self.read_m, self.reason.removesuffix(_LEFT_OUT), self.snap_m)
        return DepthCheck("left out", math.nan, self.read_m, self.reason + _LEFT_OUT, self.snap_m)

    @property
    def snapped_mm(self) -> float:
        """How far nearer the snapped depth is than the one read (mm; nan unless snapped)."""
        return 1000.0 * (self.read_m - self.z_m) if self.status == "snapped" else math.nan


def check_landmark_depth(depth_m: np.ndarray, uv: np.ndarray, ground_z: float | None = None, snap: bool = True
                         ) -> DepthCheck:
    """The depth a landmark at the depth pixel ``uv`` (2,) gets in a fit, from the depth map
    ``depth_m`` (H, W) metres: :func:`landmark_depth`, then :func:`depth_jump` against the
    surface beside it (``ground_z``: the rig's ground plane depth), snapped onto that surface
    (``snap``) or left out. The one place the fit, the CLI report and the landmark page decide it."""
    z, reason = landmark_depth(depth_m, uv)
    if not np.isfinite(z):
        # not put on the front surface beside it: measured on the real pairs as read, the 3 such
        # clicks made the held-out plants worse (docs/fit-rig.md, "From raw files to a rig")
        return DepthCheck("no depth", math.nan, math.nan, reason)
    jump, z_snap = depth_jump(depth_m, uv, z, ground_z)
    if not jump:
        return DepthCheck("ok", z, z)
    return DepthCheck("snapped", z_snap, z, jump, z_snap).snapping(snap)


_LEFT_OUT = "; left out (--no-snap-depth)"


def _nearest(mask: np.ndarray, i: int, j: int) -> float:
    vv, uu = np.nonzero(mask)
    return float(np.min(np.hypot(vv - i, uu - j))) if len(vv) else math.inf


# ---------------------------------------------------------------------- the fit
@dataclass
class _Obs:
    rec: int          # recording index
    lm: int           # landmark index within the recording
    cam: str
    uv: np.ndarray    # (2,)


class _Problem:
    """Parameter layout, residuals and Jacobian sparsity of one landmark fit."""

    def __init__(self, rig: Rig, duv: np.ndarray, z: np.ndarray, obs: list[_Obs], cams: list[str],
                 free: frozenset[str], priors: Priors, start: Rig):
        self.rig, self.start, self.priors = rig, start, priors
        self.dcam = rig.depth()
        self.duv, self.z = duv, z  # (L, 2), (L,) of the used landmarks
        self.obs, self.cams = obs, cams
        self.dfree = _free_for(free, self.dcam.name)
        self.cfree = {c: _free_for(free, c) for c in cams}
        # parameter blocks: depth intrinsics, then per camera [w (3), C (3), intrinsics]
        self.slices: dict[str, slice] = {}
        n = sum(FREE_ITEMS[k] for k in self.dfree)
        self.slices[self.dcam.name] = slice(0, n)
        for c in cams:
            m = 6 + sum(FREE_ITEMS[k] for k in self.cfree[c])
            self.slices[c] = slice(n, n + m)
            n += m
        self.n = n
        self.obs_idx = {c: np.array([i for i, o in enumerate(obs) if o.cam == c], int) for c in cams}
        self.obs_lm = np.array([o.lm for o in obs], int)
        self.obs_uv = np.array([o.uv for o in obs]).reshape(-1, 2)
        self._dcache: tuple[bytes, np.ndarray] | None = None
        #: cameras whose start pose PnP replaced: the start rig's pose was not credible, no pose prior
        self.no_pose_prior: set[str] = set()

    # intrinsics from a parameter block
    def _intr(self, base: Camera, names: list[str], p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        K, dist = base.K.copy(), base.dist.copy()
        i = 0
        for k in names:
            if k == "focal":
                K[0, 0] *= math.exp(p[i]); K[1, 1] *= math.exp(p[i])  # noqa: E702
            elif k == "principal":
                K[0, 2] += p[i]; K[1, 2] += p[i + 1]  # noqa: E702
            elif k == "k1":
                if dist.size == 0:
                    dist = np.zeros(5)
                dist[0] += p[i]
            i += FREE_ITEMS[k]
        return K, dist

    def points(self, x: np.ndarray) -> np.ndarray:
        """Landmark points (L, 3) in the rig frame for the depth intrinsics in ``x``."""
        pd = x[self.slices[self.dcam.name]]
        key = pd.tobytes()
        if self._dcache is not None and self._dcache[0] == key:
            return self._dcache[1]
        K, dist = self._intr(self.start.camera(self.dcam.name), self.dfree, pd)
        xy = cv2.undistortPoints(np.ascontiguousarray(self.duv.reshape(-1, 1, 2)), K, dist, None, np.eye(3),
                                 criteria=_UNDIST).reshape(-1, 2)
        X = np.concatenate([xy, np.ones((len(xy), 1))], axis=1) * self.z[:, None]
        X = self.dcam.to_rig(X)
        self._dcache = (key, X)
        return X

    def camera_params(self, c: str, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(R_cam_rig, t_cam_rig, K, dist) of camera ``c`` at ``x``."""
        p = x[self.slices[c]]
        base = self.start.camera(c)
        R = cv2.Rodrigues(p[:3])[0] @ base.R_cam_rig
        t = -R @ p[3:6]
        K, dist = self._intr(base, self.cfree[c], p[6:])
        return R, t, K, dist

    def project(self, x: np.ndarray, c: str, X: np.ndarray) -> np.ndarray:
        R, t, K, dist = self.camera_params(c, x)
        uv, _ = cv2.projectPoints(X.reshape(-1, 1, 3), cv2.Rodrigues(R)[0], t, K, dist)
        return uv.reshape(-1, 2)

    def residuals_px(self, x: np.ndarray) -> np.ndarray:
        """Predicted minus clicked, (n_obs, 2) pixels."""
        X = self.points(x)
        r = np.zeros((len(self.obs), 2))
        for c in self.cams:
            idx = self.obs_idx[c]
            if len(idx):
                r[idx] = self.project(x, c, X[self.obs_lm[idx]]) - self.obs_uv[idx]
        return r

    def prior_residuals(self, x: np.ndarray) -> np.ndarray:
        pr = self.priors
        out = []
        for name, names, base in ([(self.dcam.name, self.dfree, self.dcam)]
                                  + [(c, self.cfree[c], self.start.camera(c)) for c in self.cams]):
            p = x[self.slices[name]]
            i = 0
            if name != self.dcam.name:
                if name in self.no_pose_prior:
                    out += [0.0] * 6
                else:
                    out += list(p[:3] / math.radians(pr.rotation_deg))
                    out += list((p[3:6] - base.center_rig) / pr.position_m)
                i = 6
            for k in names:
                if k == "focal":
                    out.append(p[i] / pr.focal_rel)
                elif k == "principal":
                    out += list(p[i:i + 2] / (pr.principal_rel * base.width))
                elif k == "k1":
                    out.append(p[i] / pr.k1)
                i += FREE_ITEMS[k]
        return np.asarray(out)

    def fun(self, x: np.ndarray) -> np.ndarray:
        return np.concatenate([self.residuals_px(x).ravel() / self.priors.click_px, self.prior_residuals(x)])

    def sparsity(self) -> lil_matrix:
        n_obs = len(self.obs)
        n_pr = len(self.prior_residuals(self.x0()))
        S = lil_matrix((2 * n_obs + n_pr, self.n), dtype=int)
        ds = self.slices[self.dcam.name]
        for i, o in enumerate(self.obs):
            for rr in (2 * i, 2 * i + 1):
                S[rr, self.slices[o.cam]] = 1
                if ds.stop > ds.start:
                    S[rr, ds] = 1
        row = 2 * n_obs
        for name in [self.dcam.name] + self.cams:
            sl = self.slices[name]
            k = sl.stop - sl.start
            for j in range(k):  # each prior residual depends on one parameter (rotation on 3 at most)
                S[row + j, sl] = 1
            row += k
        return S

    def x0(self) -> np.ndarray:
        x = np.zeros(self.n)
        for c in self.cams:  # rotation offsets 0 (= start rotation), optical centres of the start rig
            sl = self.slices[c]
            x[sl.start + 3:sl.start + 6] = self.start.camera(c).center_rig
        return x

    def set_pose(self, x: np.ndarray, c: str, R: np.ndarray, t: np.ndarray) -> None:
        sl = self.slices[c]
        x[sl.start:sl.start + 3] = cv2.Rodrigues(R @ self.start.camera(c).R_cam_rig.T)[0].ravel()
        x[sl.start + 3:sl.start + 6] = -R.T @ t

    def to_rig(self, x: np.ndarray) -> Rig:
        rig = _copy_rig(self.start)
        K, dist = self._intr(self.start.camera(self.dcam.name), self.dfree, x[self.slices[self.dcam.name]])
        d = rig.camera(self.dcam.name)
        d.K, d.dist = K, dist
        for c in self.cams:
            R, t, K, dist = self.camera_params(c, x)
            cam = rig.camera(c)
            cam.R_cam_rig, cam.t_cam_rig, cam.K, cam.dist = R, t, K, dist
        return rig


def _copy_rig(rig: Rig) -> Rig:
    return Rig.from_dict(rig.to_dict())


def _collect(rig: Rig, recordings: Sequence[RecordingLandmarks], cameras: set[str] | None
             ) -> tuple[np.ndarray, np.ndarray, list[tuple[int, int]], list[_Obs], list[dict[str, Any]]]:
    """Depth of every landmark; returns used depth pixels (L, 2), depths (L,), their (recording,
    landmark) keys, observations (landmark index = row in L) and the rejected landmarks."""
    duv, zs, keys, obs, rejected = [], [], [], [], []
    dname = rig.depth().name
    for ri, rec in enumerate(recordings):
        for li, lm in enumerate(rec.points):
            cams = {c: uv for c, uv in lm.cameras.items() if c != dname and (cameras is None or c in cameras)}
            if not cams:
                continue
            chk = (rec.depth_checks or {}).get(li) or check_landmark_depth(rec.depth_m, lm.depth_uv, rig.ground_z,
                                                                            rec.snap_depth)
            if chk.status == "snapped":
                rejected.append({"recording": rec.name, "index": li, "note": lm.note,
                                 "depth_uv": [float(v) for v in lm.depth_uv], "reason": chk.reason,
                                 "depth_m": chk.read_m, "snapped_to_m": chk.z_m})
            if not chk.used:
                rejected.append({"recording": rec.name, "index": li, "note": lm.note,
                                 "depth_uv": [float(v) for v in lm.depth_uv], "reason": chk.reason})
                continue
            z = chk.z_m
            L = len(duv)
            duv.append(lm.depth_uv)
            zs.append(z)
            keys.append((ri, li))
            for c, uv in cams.items():
                obs.append(_Obs(ri, L, c, np.asarray(uv, float)))
    return (np.array(duv, float).reshape(-1, 2), np.array(zs, float), keys, obs, rejected)


def _min_landmarks(n_free_intrinsics: int) -> int:
    """Landmarks a camera needs: a pose is 6 unknowns and PnP with fewer than 6 points cannot
    notice a bad click; each freed intrinsic needs one more."""
    return 6 + n_free_intrinsics


def _check_degenerate(rig: Rig, X: np.ndarray, obs: list[_Obs], cams: list[str], free: frozenset[str]) -> None:
    """Raise :class:`InputError` where the landmarks cannot determine what is asked."""
    dname = rig.depth().name
    for c in cams:
        names = _free_for(free, c)
        n_int = sum(FREE_ITEMS[k] for k in names)
        idx = sorted({o.lm for o in obs if o.cam == c})
        need = _min_landmarks(n_int)
        what = "pose" + (f" and {', '.join(names)}" if names else "")
        if len(idx) < need:
            raise InputError(f"camera '{c}' has {len(idx)} landmark(s) with depth; fitting its {what} needs "
                             f"at least {need}")
        _check_spread(rig.camera(c), X[idx], c, names)
    dnames = _free_for(free, dname)
    if dnames:
        n = len(X)
        need = 6 + sum(FREE_ITEMS[k] for k in dnames)
        if n < need:
            raise InputError(f"freeing the depth camera '{dname}''s {', '.join(dnames)} needs at least {need} "
                             f"landmarks with depth; there are {n}")
        _check_spread(rig.camera(dname), X, dname, dnames)


def _check_spread(cam: Camera, X: np.ndarray, name: str, names: list[str]) -> None:
    Xc = X - X.mean(axis=0)
    s = np.linalg.svd(Xc, compute_uv=False) / math.sqrt(len(X))  # rms extents along the principal axes
    if s[0] < 0.01:
        raise InputError(f"the landmarks of camera '{name}' all lie within {100 * s[0]:.1f} cm of one spot; "
                         "spread them over the plant")
    if s[1] < 0.1 * s[0] or s[1] < 0.005:
        raise InputError(f"the landmarks of camera '{name}' lie on one line (rms {1000 * s[1]:.1f} mm off it "
                         f"over {1000 * s[0]:.0f} mm along it); add landmarks off that line")
    if "focal" in names:
        z = cam.to_cam(X)[:, 2]
        if np.std(z) < 0.02 * np.mean(z) or np.std(z) < 0.01:
            raise InputError(
                f"the landmarks of camera '{name}' all lie at about the same distance from it "
                f"({np.mean(z):.2f} m +/- {1000 * np.std(z):.0f} mm): its focal length cannot be told from its "
                "distance; add landmarks at other heights (pot rim, low and high leaves) or do not free focal")
        if "principal" in names and s[2] < 0.05 * s[0]:
            raise InputError(f"the landmarks of camera '{name}' lie in one plane: focal length and principal "
                             "point cannot both be fitted; add landmarks off that plane or free fewer intrinsics")


def _pnp_init(prob: _Problem, x: np.ndarray) -> dict[str, str]:
    """Where the start pose explains a camera's landmarks badly (median > 10 px), try
    ``cv2.solvePnPRansac`` and keep it if it explains them better. Returns notes per camera."""
    notes = {}
    X = prob.points(x)
    r = prob.residuals_px(x)
    for c in prob.cams:
        idx = prob.obs_idx[c]
        if len(idx) < 6:
            continue
        med0 = float(np.median(np.linalg.norm(r[idx], axis=1)))
        if med0 <= 10.0:
            continue
        R, t, K, dist = prob.camera_params(c, x)
        obj = np.ascontiguousarray(X[prob.obs_lm[idx]].reshape(-1, 1, 3))
        img = np.ascontiguousarray(prob.obs_uv[idx].reshape(-1, 1, 2))
        ok, rvec, tvec, inl = cv2.solvePnPRansac(obj, img, K, dist, reprojectionError=max(8.0, 0.01 * max(K[0, 0], 1)),
                                                 iterationsCount=500, confidence=0.999, flags=cv2.SOLVEPNP_SQPNP)
        if not ok:
            continue
        uv, _ = cv2.projectPoints(obj, rvec, tvec, K, dist)
        med1 = float(np.median(np.linalg.norm(uv.reshape(-1, 2) - prob.obs_uv[idx], axis=1)))
        z = (obj.reshape(-1, 3) @ cv2.Rodrigues(rvec)[0].T + tvec.ravel())[:, 2]
        if med1 < med0 and np.all(z > 0):
            R1 = cv2.Rodrigues(rvec)[0]
            prob.set_pose(x, c, R1, tvec.ravel())
            notes[c] = f"start pose from PnP/RANSAC (the start rig left a median of {med0:.1f} px, PnP {med1:.1f} px)"
            base = prob.start.camera(c)
            ang = math.degrees(np.linalg.norm(cv2.Rodrigues(R1 @ base.R_cam_rig.T)[0]))
            moved = float(np.linalg.norm(-R1.T @ tvec.ravel() - base.center_rig))
            if ang > 3 * prob.priors.rotation_deg or moved > 3 * prob.priors.position_m:
                # three sigmas off: the start rig's pose of this camera is not credible as a prior
                prob.no_pose_prior.add(c)
                notes[c] += (f"; {ang:.0f} degrees and {100 * moved:.0f} cm from the start pose: no pose prior "
                             "for this camera")
    return notes


def _solve(rig: Rig, recordings: Sequence[RecordingLandmarks], free: frozenset[str], priors: Priors,
           cameras: set[str] | None, exclude: set[tuple[int, int, str]] = frozenset(),
           check: bool = True) -> tuple[_Problem, np.ndarray, list[tuple[int, int]], list[dict], dict[str, str],
                                        np.ndarray]:
    """One robust fit. Returns (problem, solution, landmark keys, rejected, notes, outlier mask over obs)."""
    duv, z, keys, obs, rejected = _collect(rig, recordings, cameras)
    if not obs:
        raise InputError("no landmark has both a depth and a pixel in another camera")
    obs = [o for o in obs if (keys[o.lm][0], keys[o.lm][1], o.cam) not in exclude]
    cams = sorted({o.cam for o in obs})
    for c in cams:
        rig.camera(c)  # unknown camera -> InputError naming the rig's cameras
    prob = _Problem(rig, duv, z, obs, cams, free, priors, rig)
    x = prob.x0()
    if check:
        _check_degenerate(rig, prob.points(x), obs, cams, free)
    notes = _pnp_init(prob, x)
    S = prob.sparsity()
    kw = dict(jac_sparsity=S, loss="soft_l1", f_scale=priors.robust_px / priors.click_px, x_scale="jac",
              method="trf", max_nfev=200, xtol=1e-10, ftol=1e-10)
    sol = least_squares(prob.fun, x, **kw)
    x = sol.x
    # flag landmarks far off after the robust fit and fit again without them
    r = np.linalg.norm(prob.residuals_px(x), axis=1)
    thr = max(4.0 * priors.robust_px, 4.0 * float(np.median(r)))
    out = r > thr
    if out.any():
        keep = ~out
        for c in cams:
            n_left = len({o.lm for o, k in zip(obs, keep) if k and o.cam == c})
            need = _min_landmarks(sum(FREE_ITEMS[i] for i in _free_for(free, c)))
            if check and n_left < need:
                bad = sorted(((keys[o.lm], float(ri)) for o, ri, k in zip(obs, r, out) if k and o.cam == c),
                             key=lambda t: -t[1])
                raise InputError(
                    f"camera '{c}': {len(bad)} of its landmarks are off by more than {thr:.0f} px after the fit "
                    f"({', '.join(f'{recordings[a].name} #{b} {v:.0f} px' for (a, b), v in bad[:4])}); "
                    f"{n_left} left, fewer than the {need} its fit needs: check those landmarks (depth, the "
                    "same feature in both images) or add more")
        prob2 = _Problem(rig, duv, z, [o for o, k in zip(obs, keep) if k], cams, free, priors, rig)
        prob2.no_pose_prior = prob.no_pose_prior
        if all(len(prob2.obs_idx[c]) >= 4 for c in cams):
            sol = least_squares(prob2.fun, x, jac_sparsity=prob2.sparsity(), **{k: v for k, v in kw.items()
                                                                               if k != "jac_sparsity"})
            x = sol.x
    return prob, x, keys, rejected, notes, out


def fit_rig(rig: Rig, recordings: Sequence[RecordingLandmarks], *, free: Iterable[str] = frozenset(),
            priors: Priors | None = None, cameras: Iterable[str] | None = None, loo: bool | None = None,
            max_median_px: float | None = None) -> FitResult:
    """Fit ``rig``'s cameras to the landmarks of ``recordings`` (all jointly).

    ``free``: items of :func:`parse_free`; ``cameras``: fit these cameras (each must have enough
    landmarks); default: every camera with enough landmarks -- a camera with too few that is not
    named in ``free`` keeps its start pose and is named in a warning (a partial fit).
    ``loo``: leave-one-recording-out residuals (None = when there are >= 2 recordings; True with
    one recording raises :class:`InputError`); a camera without a leave-one-recording-out figure
    gets leave-one-landmark-out instead. ``max_median_px``: a camera whose fitted median residual
    exceeds it raises :class:`InputError` (the landmarks and the rig disagree: wrong pairs, wrong
    start, wrong camera model).
    Raises :class:`InputError` for degenerate input (too few landmarks, collinear, all at one
    distance when focal is free, a camera left with too few after outlier rejection, ...).
    Returns the fitted rig, a JSON-able report and warnings.
    """
    t0 = time.perf_counter()
    free = frozenset(free) if not isinstance(free, str) else parse_free(free)
    priors = priors or Priors()
    cams_sel = set(cameras) if cameras is not None else None
    loo_asked = loo
    if loo and len(recordings) < 2:
        raise InputError("leave-one-recording-out needs landmarks from at least two recordings")
    dname = rig.depth().name
    for it in free:
        if ":" in it and it.split(":", 1)[0] not in rig.names:
            raise InputError(f"cannot free '{it}': the rig has no camera '{it.split(':', 1)[0]}'")
    if cams_sel is not None:
        for c in sorted(cams_sel):
            rig.camera(c)  # unknown camera -> InputError naming the rig's cameras
    not_fitted = {} if cams_sel is not None else _thin_cameras(rig, recordings, free)
    if not_fitted:
        cams_sel = {o.cam for o in _collect(rig, recordings, None)[3]} - set(not_fitted)
        if not cams_sel:  # nothing to fit: the first camera's own message
            cams_sel = None
            not_fitted = {}
    prob, x, keys, rejected, notes, out = _solve(rig, recordings, free, priors, cams_sel)
    fitted = prob.to_rig(x)
    try:  # a rig no tool could load afterwards (a lens model folding the image) is no result
        Rig.from_dict(fitted.to_dict())
    except InputError as e:
        raise InputError(f"the fitted rig is not usable ({e.detail}): the start lens is too far from the real one "
                         "for the terms freed -- start from a better lens (the camera's own calibration, a focal "
                         "length) or free fewer terms") from None
    r = prob.residuals_px(x)
    rows = []
    for i, o in enumerate(prob.obs):
        ri, li = keys[o.lm]
        rows.append({"recording": recordings[ri].name, "index": li, "note": recordings[ri].points[li].note,
                     "camera": o.cam, "residual_px": float(np.hypot(*r[i])), "du": float(r[i, 0]),
                     "dv": float(r[i, 1]), "depth_m": float(prob.z[o.lm]), "outlier": bool(out[i])})
    rows.sort(key=lambda d: -d["residual_px"])
    snapped = [d for d in rejected if "snapped_to_m" in d]
    rejected = [d for d in rejected if "snapped_to_m" not in d]
    warnings = [f"landmark {d['index']} of {d['recording']} ({d['note'] or 'no note'}) not used: {d['reason']}"
                for d in rejected]
    warnings += [f"landmark {d['index']} of {d['recording']} ({d['note'] or 'no note'}): {d['reason']}; snapped to "
                 f"{d['snapped_to_m']:.3f} m" for d in snapped]
    warnings += [f"{d['camera']}: landmark {d['index']} of {d['recording']} is off by {d['residual_px']:.1f} px "
                 "and was left out of the fit (an outlier)" for d in rows if d["outlier"]]
    warnings += [f"camera '{c}' not fitted, kept at its start pose: {why}" for c, why in sorted(not_fitted.items())]
    warnings += [f"{c}: {n}" for c, n in sorted(notes.items())]
    report: dict[str, Any] = {
        "method": "landmarks",
        "free": sorted(free),
        "fitted_cameras": prob.cams + ([dname] if prob.dfree else []),
        "priors": asdict(priors),
        "landmarks_used": len(keys),
        "observations_used": int((~out).sum()),
        "landmarks_rejected": rejected,
        "landmarks_snapped": snapped,
        "start_notes": notes,
        "per_camera": _stats_by(rows, ("camera",)),
        "per_recording": _nested_stats(rows),
        "residuals": rows,
        "changes": _changes(rig, fitted, prob.cams + [dname]),
        "not_fitted": not_fitted,
    }
    if max_median_px is not None:
        bad = {c: s["median_px"] for c, s in report["per_camera"].items() if s["median_px"] > max_median_px}
        if bad:
            c, m = max(bad.items(), key=lambda t: t[1])
            raise InputError(
                f"camera '{c}': median landmark residual {m:.1f} px after the fit, above the {max_median_px:g} px a "
                "usable rig leaves (--max-median): the landmarks do not fit one camera model -- check the pairs "
                "(the same feature in both images?), the start rig (turn, lens) or what is freed")
    if loo is None:
        loo = len(recordings) >= 2
    report["landmark_depths"] = [{"recording": recordings[ri].name, "index": li, "depth_m": float(prob.z[L])}
                                 for L, (ri, li) in enumerate(keys)]
    if loo:
        report["leave_one_out"] = _leave_one_out(rig, recordings, free, priors, cams_sel)
        for rec, v in report["leave_one_out"]["per_recording"].items():
            if "unavailable" in v:
                warnings.append(f"leave-one-out without {rec}: {v['unavailable']}")
            else:
                warnings += [f"leave-one-out without {rec}, camera {c}: {s['unavailable']}"
                             for c, s in v.items() if "unavailable" in s]
    else:
        report["leave_one_out"] = {"unavailable": "needs landmarks from at least two recordings"}
    lolo_cams = set(prob.cams) - set(report["leave_one_out"].get("per_camera", {}))
    if lolo_cams and loo_asked is not False:
        lolo = _leave_one_landmark_out(rig, recordings, free, priors, prob.cams, lolo_cams,
                                       {(keys[o.lm], o.cam) for o, k in zip(prob.obs, out) if k})
        report["leave_one_landmark_out"] = lolo
        for c, s in lolo.items():
            if "unavailable" in s:
                warnings.append(f"{c}: no leave-one-out figure ({s['unavailable']}): its fitted residuals are the "
                                "only measure, and they flatter the rig")
    report["time_s"] = round(time.perf_counter() - t0, 3)
    return FitResult(fitted, report, warnings)


def _stats(vals: list[float]) -> dict[str, Any]:
    a = np.asarray(vals, float)
    return {"n": int(a.size), "median_px": float(np.median(a)), "p90_px": float(np.percentile(a, 90)),
            "max_px": float(a.max())}


def _stats_by(rows: list[dict], key: tuple[str, ...]) -> dict[str, Any]:
    groups: dict[str, list[float]] = {}
    for d in rows:
        if not d.get("outlier"):
            groups.setdefault(d[key[0]], []).append(d["residual_px"])
    return {k: _stats(v) for k, v in sorted(groups.items())}


def _nested_stats(rows: list[dict]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for rec in sorted({d["recording"] for d in rows}):
        out[rec] = _stats_by([d for d in rows if d["recording"] == rec], ("camera",))
    return out


def evaluate_landmarks(rig: Rig, recordings: Sequence[RecordingLandmarks], cameras: Iterable[str] | None = None
                       ) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """Residuals of ``rig`` on landmarks without fitting (e.g. independent landmarks kept out of
    the fit, or the live residual next to a point being clicked).

    Returns ``(rows, rejected)``: per landmark and camera ``{"recording", "index", "note",
    "camera", "residual_px", "du", "dv"}`` (predicted minus clicked, px), worst first; and the
    landmarks without depth, with the reason."""
    cams = set(cameras) if cameras is not None else None
    duv, z, keys, obs, rejected = _collect(rig, recordings, cams)
    if not obs:
        return [], rejected
    dcam = rig.depth()
    xy = dcam.undistort_normalized(duv)
    X = dcam.to_rig(np.concatenate([xy, np.ones((len(xy), 1))], axis=1) * z[:, None])
    rows = []
    for o in obs:
        ri, li = keys[o.lm]
        uv, _ = rig.camera(o.cam).project(X[o.lm][None])
        d = uv[0] - o.uv
        rows.append({"recording": recordings[ri].name, "index": li, "note": recordings[ri].points[li].note,
                     "camera": o.cam, "residual_px": float(np.hypot(*d)), "du": float(d[0]), "dv": float(d[1])})
    rows.sort(key=lambda d: -d["residual_px"])
    return rows, rejected


def _leave_one_out(rig: Rig, recordings: Sequence[RecordingLandmarks], free: frozenset[str], priors: Priors,
                   cams_sel: set[str] | None) -> dict[str, Any]:
    """Fit without each recording in turn and measure that recording's residuals (px). A camera
    with too few landmarks in the other recordings is left out of that fold (and said so)."""
    per_rec: dict[str, Any] = {}
    held: list[dict] = []
    dname = rig.depth().name
    for k, rec in enumerate(recordings):
        rest = [r for i, r in enumerate(recordings) if i != k]
        counts: dict[str, int] = {}
        for r in rest:
            for lm in r.points:
                for c in lm.cameras:
                    if c != dname and (cams_sel is None or c in cams_sel):
                        counts[c] = counts.get(c, 0) + 1
        mine = {c for lm in rec.points for c in lm.cameras if c != dname and (cams_sel is None or c in cams_sel)}
        thin = {c: f"{counts.get(c, 0)} landmark(s) in the other recordings, fewer than the "
                   f"{_min_landmarks(sum(FREE_ITEMS[i] for i in _free_for(free, c)))} a fit needs"
                for c in mine
                if counts.get(c, 0) < _min_landmarks(sum(FREE_ITEMS[i] for i in _free_for(free, c)))}
        use = {c for c in counts if c not in thin}
        if not use & mine:
            per_rec[rec.name] = {"unavailable": "; ".join(f"{c}: {w}" for c, w in sorted(thin.items()))
                                 or "no camera of this recording has landmarks elsewhere"}
            continue
        try:
            prob, x, *_ = _solve(rig, rest, free, priors, use)
        except InputError as e:
            per_rec[rec.name] = {"unavailable": str(e)}
            continue
        rows, _rej = evaluate_landmarks(prob.to_rig(x), [rec], set(prob.cams))
        stats = _stats_by(rows, ("camera",)) if rows else {}
        stats.update({c: {"unavailable": w} for c, w in thin.items()})
        per_rec[rec.name] = stats
        held += rows
    return {"per_recording": per_rec, "per_camera": _stats_by(held, ("camera",)) if held else {}}


def _thin_cameras(rig: Rig, recordings: Sequence[RecordingLandmarks], free: frozenset[str]) -> dict[str, str]:
    """Cameras with fewer landmarks (with depth) than their fit needs, not named in ``free``
    (a camera asked for by name is refused instead): camera -> reason."""
    obs = _collect(rig, recordings, None)[3]
    out = {}
    for c in sorted({o.cam for o in obs}):
        if any(it.startswith(f"{c}:") for it in free):
            continue
        n = len({o.lm for o in obs if o.cam == c})
        need = _min_landmarks(sum(FREE_ITEMS[k] for k in _free_for(free, c)))
        if n < need:
            out[c] = f"{n} landmark(s) with depth, fewer than the {need} its fit needs"
    return out


def _leave_one_landmark_out(rig: Rig, recordings: Sequence[RecordingLandmarks], free: frozenset[str],
                            priors: Priors, cams: list[str], report_cams: set[str],
                            outliers: set[tuple[tuple[int, int], str]]) -> dict[str, Any]:
    """Per camera in ``report_cams``: each of its landmarks (outliers of the full fit aside)
    measured against the rig fitted without that landmark (in every camera). For a camera whose
    recordings cannot be left out one at a time."""
    duv, z, keys, obs, _rej = _collect(rig, recordings, set(cams))
    held: dict[str, list[float]] = {c: [] for c in report_cams}
    why: dict[str, str] = {}
    for L, key in enumerate(keys):
        mine = [o.cam for o in obs if o.lm == L and o.cam in report_cams and (key, o.cam) not in outliers]
        if not mine:
            continue
        try:
            prob, x, *_ = _solve(rig, recordings, free, priors, set(cams),
                                 exclude={(key[0], key[1], c) for c in cams})
        except InputError as e:
            for c in mine:
                why.setdefault(c, str(e))
            continue
        ri, li = key
        fitted = prob.to_rig(x)
        rows, _ = evaluate_landmarks(fitted, [RecordingLandmarks(recordings[ri].name, recordings[ri].depth_m,
                                                                 [recordings[ri].points[li]])],
                                     [c for c in mine if c in prob.cams])
        for d in rows:
            held[d["camera"]].append(d["residual_px"])
    out: dict[str, Any] = {}
    for c in sorted(report_cams):
        if held[c]:
            out[c] = {**_stats(held[c]), "kind": "leave-one-landmark-out"}
        else:
            out[c] = {"unavailable": why.get(c, "no landmark of this camera can be left out")}
    return out


def keep_not_worse(before: Rig, after: Rig, cams_report: dict[str, Any], stage: str,
                   landmark_slack_px: float = 0.25) -> tuple[Rig, list[str]]:
    """After an image-based stage (``--refine``, ``--silhouette``): every camera of
    ``cams_report`` (camera -> the stage's report: ``start_cost``/``end_cost``, landmark errors
    before/after) whose own cost rose, or whose landmarks' median error rose by more than
    ``landmark_slack_px``, gets its camera from ``before`` back (``"reverted"`` in its report).
    Returns the rig and a warning per reverted camera."""
    out = _copy_rig(after)
    warnings = []
    for name, r in cams_report.items():
        if not isinstance(r, dict):
            continue
        why = []
        sc, ec = r.get("start_cost"), r.get("end_cost")
        if isinstance(sc, (int, float)) and isinstance(ec, (int, float)) and ec > sc * (1 + 1e-9) + 1e-12:
            why.append(f"its {stage} cost rose from {sc:.4g} to {ec:.4g}")
        if isinstance(r.get("landmarks_px"), dict):  # refine: {"before": stats, "after": stats}
            b, a = (r["landmarks_px"].get(k, {}).get("median_px") for k in ("before", "after"))
        else:  # silhouette: per view lists
            vb = [e for v in r.get("views", {}).values() for e in v.get("landmarks_px", [])]
            va = [e for v in r.get("views", {}).values() for e in v.get("landmarks_px_after", [])]
            b, a = (float(np.median(vb)), float(np.median(va))) if vb and va else (None, None)
        if b is not None and a is not None and a > b + landmark_slack_px:
            why.append(f"its landmarks' median error rose from {b:.2f} to {a:.2f} px")
        if why:
            out.cameras = [Camera.from_dict(before.camera(name).to_dict()) if c.name == name else c
                           for c in out.cameras]
            r["reverted"] = "; ".join(why)
            warnings.append(f"{name}: {stage} made it worse ({r['reverted']}): its camera before the {stage} is "
                            "kept")
    return out, warnings


def _changes(start: Rig, fitted: Rig, names: list[str]) -> dict[str, Any]:
    out = {}
    for n in names:
        a, b = start.camera(n), fitted.camera(n)
        dR = b.R_cam_rig @ a.R_cam_rig.T
        ang = math.degrees(math.acos(np.clip((np.trace(dR) - 1) / 2, -1, 1)))
        out[n] = {"rotation_deg": ang, "position_m": float(np.linalg.norm(b.center_rig - a.center_rig)),
                  "focal_rel": float(b.K[0, 0] / a.K[0, 0] - 1.0),
                  "principal_px": [float(b.K[0, 2] - a.K[0, 2]), float(b.K[1, 2] - a.K[1, 2])],
                  "k1": float((b.dist[0] if b.dist.size else 0.0) - (a.dist[0] if a.dist.size else 0.0))}
    return out


# ---------------------------------------------------------------------- from files
def load_recording_landmarks(rig: Rig, landmarks: LandmarkSet) -> list[RecordingLandmarks]:
    """Depth maps (metres) of the landmark file's recordings, paired with their points."""
    from ..data.recording import Recording

    out = []
    for key, pts in landmarks.recordings.items():
        if not pts:
            continue
        folder = landmarks.folder(key)
        try:
            rec = Recording.load(folder)
            rec.check(rig, need_depth=True)
        except InputError as e:
            raise InputError(f"recording '{key}' of the landmarks file: {e}", landmarks.path) from None
        out.append(RecordingLandmarks(key, rec.depth_m(rig.depth_scale), pts))
    return out


def fit_rig_from_file(rig: Rig, landmarks: LandmarkSet, snap_depth: bool = True, **kw: Any) -> FitResult:
    """:func:`fit_rig` on the recordings named in a landmarks file (checked against ``rig``);
    ``snap_depth``: see :attr:`RecordingLandmarks.snap_depth`."""
    landmarks.check(rig)
    landmarks.check_recordings()
    recs = load_recording_landmarks(rig, landmarks)
    for r in recs:
        r.snap_depth = snap_depth
    try:
        return fit_rig(rig, recs, **kw)
    except InputError as e:  # what the landmarks do not determine: named as the landmarks file's problem
        if e.path is not None or landmarks.path is None or e.detail.startswith("cannot free"):
            raise
        raise InputError(e.detail, landmarks.path) from None


def format_report(report: dict[str, Any], worst: int = 10) -> str:
    """The per-camera residual table, leave-one-out and the worst landmarks, as text."""
    lines = [f"landmark fit: {report['landmarks_used']} landmarks, {report['observations_used']} pixel pairs used"
             + (f", free: {', '.join(report['free'])}" if report["free"] else "")]
    loo = dict(report.get("leave_one_out", {}).get("per_camera", {}))
    lolo = {c: s for c, s in report.get("leave_one_landmark_out", {}).items() if "median_px" in s}
    lines.append(f"  {'camera':<16}{'n':>5}{'median px':>11}{'p90 px':>9}{'max px':>9}{'LOO median':>12}")
    for c, s in report["per_camera"].items():
        lo = (f"{loo[c]['median_px']:12.2f}" if c in loo else f"{lolo[c]['median_px']:11.2f}L" if c in lolo
              else f"{'none':>12}")
        lines.append(f"  {c:<16}{s['n']:>5}{s['median_px']:11.2f}{s['p90_px']:9.2f}{s['max_px']:9.2f}{lo}")
    if lolo:
        lines.append("  (L: leave-one-landmark-out; the others leave one recording out)")
    for c, n in sorted(report.get("start_notes", {}).items()):
        lines.append(f"  start, {c}: {n}")
    for c, n in sorted(report.get("not_fitted", {}).items()):
        lines.append(f"  NOT FITTED, {c}: kept at its start pose ({n})")
    per_rec = report.get("per_recording", {})
    if len(per_rec) > 1:
        lines.append("  per recording (median px):")
        for rec, cams in per_rec.items():
            lines.append(f"    {rec}: " + "  ".join(f"{c} {s['median_px']:.2f}" for c, s in cams.items()))
    lines.append("  worst landmarks:")
    for d in report["residuals"][:worst]:
        lines.append(f"    {d['residual_px']:7.2f} px  {d['camera']:<14} {d['recording']} #{d['index']}"
                     + (f" at {d['depth_m']:.3f} m" if "depth_m" in d else "")
                     + (f" ({d['note']})" if d["note"] else "") + ("  [outlier]" if d["outlier"] else ""))
    return "\n".join(lines)
