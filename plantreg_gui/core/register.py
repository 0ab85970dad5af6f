"""Registration engine: depth mesh -> target rays -> source cameras -> registered images + cases.

Method (Stumpe et al.; details and the edge-cut geometry in :mod:`.mesh`, user documentation in
``docs/registration.md``):

1. Object mesh from the depth map (ROI crop, back-projection through the depth camera's
   intrinsics and distortion, 8-neighbourhood triangulation, edge cut), and the uncertainty
   mesh: the object mesh's boundary edges extruded along the depth camera's rays to the ground.
2. Target rays through the undistorted target pixel centres are cast once into both meshes
   (Open3D ``RaycastingScene``); the first object-mesh hit is the pixel's 3D point.
3. For every source camera the point is projected through the source's distortion model; a ray
   from the *source camera centre* towards the point (never from the surface, which would hit
   itself) tests for occlusion by the object mesh and for passing through the uncertainty mesh.
4. Values are sampled bilinearly from the raw source image at the projected position.

Case codes per target pixel and source camera (``cases[source]``, uint8):
  0 = P6 certain background (target ray hits neither mesh)
  1 = P1 legitimate
  2 = P2 occlusion (a ray from the source camera towards the hit point meets the object mesh first)
  3 = P3.1 incoming uncertain (the target ray meets the uncertainty mesh before the object mesh)
  4 = P3.2 outgoing uncertain (the source ray meets the uncertainty mesh before the point)
  5 = P5 uncertain object area with no object-mesh hit behind
  6 = hit outside the source image or behind the source camera
Area codes (target only, ``area``): 4 = P4 certain object, 5 = P5 uncertain object area, 6 = P6 background.

Precedence when several apply to an object hit: 6 > 2 > 3 > 4 > 1. Outside the source (6) there is
no value at all; a certain occlusion (2) is a statement about *measured* geometry and means the
value is wrong, so it outranks mere uncertainty; incoming uncertainty (3) puts the target point
itself in doubt (for every source) and so outranks outgoing uncertainty (4), which concerns only
this source's view of an otherwise certain point. "Before" means by more than ``occlusion_tol_m``
(object mesh) or ``uncertainty_tol_m`` (uncertainty mesh), so that a surface does not occlude
itself and the boundary edge shared by both meshes does not count.
"""

from __future__ import annotations

import hashlib
import time
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any, Callable, Iterator

import numpy as np

from .camera import Camera
from .cases import AREA_NAMES, CASE_NAMES, Area, Case  # noqa: F401 (re-exported)
from .errors import InputError
from .mesh import TriMesh, extend_boundary, object_mesh, uncertainty_mesh
from .progress import Reporter, ensure_reporter
from .raycast import (NEAR_CAMERA_M, RAY_CHUNK, ConeMarks, MeshScene, RayGrid, cast_where, cone_marks,
                      pixel_rays_cam, pixel_rays_toward, project_points, ray_grid)
from .recording import Recording
from .rig import Rig

# the codes are defined once in .cases; these names stay importable from here
CASE_BACKGROUND, CASE_P1, CASE_P2, CASE_P31, CASE_P32, CASE_P5, CASE_OUTSIDE = (
    Case.BACKGROUND, Case.P1, Case.P2, Case.P31, Case.P32, Case.P5, Case.OUTSIDE)
AREA_P4, AREA_P5, AREA_P6 = Area.P4, Area.P5, Area.P6


@dataclass
class RegistrationParams:
    edge_angle_deg: float = 15.0        # mesh edge cut (see mesh.py for the geometry)
    occlusion_tol_m: float = 0.002      # a source-ray hit this much before the point counts as occluding
    roi_min: np.ndarray | None = None   # override the rig's ROI (3,) metres
    roi_max: np.ndarray | None = None
    uncertainty_tol_m: float = 0.002    # an uncertainty-mesh hit this much before the point counts (P3.1, P3.2)
    boundary_px: float = 0.5            # skirt around the object mesh's boundary, depth pixels (0 = none)
    # ToF clean-up before meshing (core/depthfilter.py, docs/registration.md section 1a)
    flying_filter: bool = True          # remove flying pixels (depth between two surfaces)
    flying_jump_rel: float = 0.01       # a depth jump counts above this fraction of the depth (1 cm at 1 m)
    flying_repair: bool = True          # move flying pixels onto the surface they mostly saw (False: remove)
    fill_holes: bool = True             # fill holes between two measured pixels of one surface (steep flanks)
    denoise: bool = True                # edge-preserving same-surface plane fit
    denoise_size: int = 3               # window of the plane fit, depth pixels (odd; 5 = smoother, 3x slower)
    denoise_tol_rel: float = 0.01       # same surface: |dz| <= this fraction of the depth
    mixed_radius_px: float = 1.0        # mixed-pixel flag: source px around a silhouette (+ 2 x camera blur_px)

    def to_dict(self) -> dict[str, Any]:
        return {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in self.__dict__.items()}

    def roi(self, rig: Rig) -> tuple[np.ndarray, np.ndarray]:
        lo = rig.roi_min if self.roi_min is None else np.asarray(self.roi_min, dtype=np.float64)
        hi = rig.roi_max if self.roi_max is None else np.asarray(self.roi_max, dtype=np.float64)
        return lo, hi


@dataclass
class RegistrationResult:
    """All arrays are in the target camera's pixel grid, (H, W[, ...]).

    ``points_rig`` (H, W, 3) float32: first object-mesh hit of each target ray, NaN if none.
    ``registered[cam]`` (H, W) or (H, W, B) float32, NaN where not mapped, for every camera incl. the target;
    above :data:`DENSE_LIMIT_BYTES` (cubes: see :func:`keep_at_hits`) a :class:`~.hits.HitImage` (values at the hits only; behaves
    like the array: ``np.asarray``, indexing, ``.shape``).
    ``source_uv[cam]`` (H, W, 2) float32 distorted source pixel coordinates of the hit (NaN if none).
    ``cases[cam]`` (H, W) uint8 for every camera except the target. ``area`` (H, W) uint8.
    ``timings`` stage name -> seconds.
    """

    target: str
    points_rig: np.ndarray
    area: np.ndarray
    registered: dict[str, np.ndarray]
    source_uv: dict[str, np.ndarray]
    cases: dict[str, np.ndarray]
    params: RegistrationParams
    timings: dict[str, float] = field(default_factory=dict)
    stats: dict[str, Any] = field(default_factory=dict)
    #: (H_depth, W_depth) bool: depth pixels removed as flying before meshing (depth camera's grid)
    flying: np.ndarray | None = None
    #: source camera -> (H, W) bool: P1 pixels whose footprint in the source reaches across a
    #: silhouette of the object mesh (see core/mixed.py); statistics can exclude them
    mixed: dict[str, np.ndarray] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)  # sentences for the user (e.g. core.roi.cut_warning)

    @property
    def shape(self) -> tuple[int, int]:
        return self.area.shape  # type: ignore[return-value]

    def case_counts(self) -> dict[str, dict[int, int]]:
        # bincount, not np.unique: no sort of H x W codes (0.1 s per camera in a 4K view)
        out = {}
        for cam, c in self.cases.items():
            counts = np.bincount(np.asarray(c, dtype=np.uint8).ravel())
            out[cam] = {int(k): int(counts[k]) for k in np.flatnonzero(counts)}
        return out


# ---------------------------------------------------------------------------- sampling
#: Result arrays in this size range are allocated from a plain anonymous mapping (see nan_array).
_PLAIN_PAGES_BYTES = (64 << 20, 1 << 30)


def nan_array(shape: tuple[int, ...]) -> np.ndarray:
    """``np.full(shape, nan, float32)``; arrays of 64 MB .. 1 GB come from a plain anonymous ``mmap``.

    Why: numpy asks the kernel for transparent huge pages on large allocations; where the kernel
    compacts memory on demand for them (``defrag = madvise``, a common default) the first touch
    of a fresh result stalls while it assembles 2 MB pages -- measured here 0.6-0.8 s for the
    300 MB of a 204-band cube registered into the 640x576 infrared view, against 0.15 s with
    ordinary pages. For multi-gigabyte results (the same cube in a 4K view: 6.8 GB) the number of
    page faults dominates instead, and huge pages are the faster choice (measured 5-18 s vs 18-22 s).
    """
    n = int(np.prod(shape))
    lo, hi = _PLAIN_PAGES_BYTES
    if not lo <= n * 4 <= hi:
        return np.full(shape, np.nan, dtype=np.float32)
    import mmap

    buf = mmap.mmap(-1, n * 4)
    a = np.frombuffer(buf, dtype=np.float32, count=n).reshape(shape)
    a.fill(np.nan)
    return a


#: Samples of a band-sequential cube gathered and written together: their (C, rows) float32
#: block (3.3 MB for 204 bands) is still in cache when it is written out transposed (sampling the
#: 204-band cube into the infrared or the 4K view: -10 to -15 % CPU against 64 MB blocks; same values).
_BAND_ROWS = 1 << 12


def _sample_chunk_rows(n_channels: int) -> int:
    # ~64 MB of float32 output per chunk
    return int(min(RAY_CHUNK, max(1 << 14, (64 << 20) // (4 * max(1, n_channels)))))


#: Threads that sample a band-sequential cube (``sample_bilinear``); 1 = the calling thread only.
#: None: the cores (at most 2) when there are at least :data:`_THREAD_MIN_VALUES` values to sample.
SAMPLE_THREADS: int | None = None
_THREAD_MIN_VALUES = 1 << 24


def _sample_threads(n: int, C: int) -> int:
    import os

    if SAMPLE_THREADS is not None:
        return max(1, int(SAMPLE_THREADS))
    return min(2, os.cpu_count() or 1) if n * C >= _THREAD_MIN_VALUES else 1


def sample_bilinear(image: np.ndarray, uv: np.ndarray, progress: Reporter | None = None, *,
                    out: np.ndarray | None = None, rows: np.ndarray | None = None,
                    done: Callable[[int], None] | None = None, threads: int | None = None) -> np.ndarray:
    """Bilinear samples of ``image`` (h, w) or (h, w, C), any dtype, at pixel positions ``uv``
    (N, 2) (pixel centres at integers) -> (N,) or (N, C) float32. NaN rows of ``uv`` give NaN.

    With ``out`` (M, C) float32 (its contents need not be set) and ``rows`` (N,), sample i is
    written to ``out[rows[i]]`` instead, every other row of ``out`` (not in ``rows``, or with NaN
    ``uv``) is set to NaN, and ``out`` is returned: no NaN pass over rows that get a sample.

    Positions in the half-pixel border of the image take the edge pixel's value (clamped).
    Exact (no fixed-point weights as in ``cv2.remap``, which also handles at most 4 channels).
    Pixel-interleaved images with a few channels are gathered directly; with many channels
    (BIP hyperspectral cubes) a sparse (N x h*w) interpolation matrix multiplies the (h*w, C)
    cube, reading each pixel's spectrum contiguously; band-sequential cubes (ENVI BSQ loads as a
    (h, w, C) view of a (C, h, w) array) are gathered a few bands at a time so that each band
    stays in cache. No copy of the cube is made in either layout.

    ``done(k)``, with ``out`` and ascending ``rows``: called on this thread whenever the first
    ``k`` rows of ``out`` are final (a reader may take them while the rest is sampled).
    ``threads``: sampling threads for a band-sequential cube (default :func:`_sample_threads`).
    """
    progress = ensure_reporter(progress)
    img = np.asarray(image)
    h, w = img.shape[:2]
    if img.ndim > 3:
        img = img.reshape(h, w, -1)
    C = 1 if img.ndim == 2 else img.shape[2]
    band_first = C > 1 and img.transpose(2, 0, 1).flags.c_contiguous and not img.flags.c_contiguous
    if band_first:
        planes = img.transpose(2, 0, 1).reshape(C, h * w)
    else:
        flat = np.ascontiguousarray(img).reshape(h * w, C)
        if C > 4 and flat.dtype != np.float32:
            flat = flat.astype(np.float32)  # once, not per chunk (scipy would convert the whole cube)
    uv = np.asarray(uv)
    n = len(uv)
    squeeze = out is None and C == 1
    if out is None:
        out = np.full((n, C), np.nan, dtype=np.float32)
        rows_all = np.arange(n)
    else:
        out = out.reshape(len(out), C)
        rows_all = np.asarray(rows)
    ok = np.flatnonzero(np.isfinite(uv).all(axis=1))
    if rows is not None:
        unsampled = np.ones(len(out), dtype=bool)
        unsampled[rows_all[ok]] = False
        out[unsampled] = np.nan
    step = _sample_chunk_rows(C)
    du = 1 if w > 1 else 0
    dv = w if h > 1 else 0
    n_threads = (threads or _sample_threads(len(ok), C)) if band_first else 1
    ascending = rows is not None and (len(rows_all) < 2 or bool(np.all(rows_all[1:] > rows_all[:-1])))
    if done is not None and band_first:
        step = min(step, 4 * _BAND_ROWS)  # a reader waits for at most ~13 MB of a 204-band cube

    def report(a: int) -> None:  # chunk ``a`` (and every one before it) is written
        if done is not None and ascending:
            end = min(a + step, len(ok))
            done(len(out) if end == len(ok) else int(rows_all[ok[end]]))
    if n_threads > 1:  # chunks small enough that every thread gets several (load balance)
        per = -(-len(ok) // (4 * n_threads))
        step = min(step, max(_BAND_ROWS, -(-per // _BAND_ROWS) * _BAND_ROWS))

    def chunk(a: int) -> None:
        sel = ok[a : a + step]
        u = np.clip(uv[sel, 0].astype(np.float64), 0, w - 1)
        v = np.clip(uv[sel, 1].astype(np.float64), 0, h - 1)
        u0 = np.minimum(np.floor(u), max(w - 2, 0)).astype(np.int64)
        v0 = np.minimum(np.floor(v), max(h - 2, 0)).astype(np.int64)
        fu = (u - u0).astype(np.float32)
        fv = (v - v0).astype(np.float32)
        i00 = v0 * w + u0
        w00, w01 = (1 - fu) * (1 - fv), fu * (1 - fv)
        w10, w11 = (1 - fu) * fv, fu * fv
        dst = rows_all[sel]
        if band_first:
            idx = np.stack([i00, i00 + du, i00 + dv, i00 + dv + du])  # (4, m)
            wts = np.stack([w00, w01, w10, w11])
            m = len(sel)
            acc = np.empty((C, min(m, _BAND_ROWS)), dtype=np.float32)
            for t0 in range(0, m, _BAND_ROWS):
                t1 = min(m, t0 + _BAND_ROWS)
                A = acc[:, : t1 - t0]
                for b0 in range(0, C, 4):
                    blk = planes[b0 : b0 + 4]  # a few bands: ~1 MB each, kept in cache for the 4 gathers
                    g = np.take(blk, idx[:, t0:t1], axis=1).astype(np.float32, copy=False)  # (nb, 4, rows)
                    np.einsum("bkm,km->bm", g, wts[:, t0:t1], out=A[b0 : b0 + 4])
                out[dst[t0:t1]] = A.T
            return
        if C <= 4:
            acc = flat[i00].astype(np.float32) * w00[:, None]
            acc += flat[i00 + du] * w01[:, None]
            acc += flat[i00 + dv] * w10[:, None]
            acc += flat[i00 + dv + du] * w11[:, None]
        else:
            import scipy.sparse as sp

            m = len(sel)
            cols = np.stack([i00, i00 + du, i00 + dv, i00 + dv + du], axis=1).ravel()
            wts = np.stack([w00, w01, w10, w11], axis=1).ravel()
            M = sp.csr_matrix((wts, cols, np.arange(0, 4 * m + 1, 4)), shape=(m, h * w))
            acc = M @ flat
        out[dst] = acc

    starts = range(0, len(ok), step)
    if n_threads <= 1:
        for a in starts:
            progress(a / max(1, len(ok)))
            chunk(a)
            report(a)
        if done is not None:
            done(len(out))
        return out[:, 0] if squeeze else out
    # band-sequential cubes: chunks in threads (numpy's take, einsum and the scatter release the
    # GIL); progress and cancellation stay on this thread; chunks write disjoint rows of ``out``
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(n_threads, thread_name_prefix="plantreg-sample") as ex:
        try:
            futures = [ex.submit(chunk, a) for a in starts]
            for a, f in zip(starts, futures):
                progress(a / max(1, len(ok)))
                f.result()
                report(a)
        except BaseException:
            ex.shutdown(wait=True, cancel_futures=True)
            raise
    if done is not None:
        done(len(out))
    return out[:, 0] if squeeze else out


# ---------------------------------------------------------------------------- mesh helpers
@dataclass
class Meshes:
    """Object and uncertainty mesh of one depth map, with their ray-casting scenes."""

    object: TriMesh
    uncertainty: TriMesh
    object_scene: MeshScene
    uncertainty_scene: MeshScene
    flying: np.ndarray | None = None  # (H, W) bool depth pixels removed as flying
    filled: np.ndarray | None = None  # (H, W) bool holes filled before meshing (depthfilter.fill_holes)


def build_meshes(rig: Rig, depth_m: np.ndarray, params: RegistrationParams | None = None,
                 rays_cam: np.ndarray | None = None, progress: Reporter | None = None,
                 timings: dict[str, float] | None = None) -> Meshes:
    """Object mesh + uncertainty mesh + scenes of depth map ``depth_m`` (H, W metres, NaN = none)."""
    params = params or RegistrationParams()
    progress = ensure_reporter(progress)
    timings = {} if timings is None else timings
    depth_raw = depth_m
    dcam = rig.depth()
    lo, hi = params.roi(rig)
    with _stage(progress, timings, "depth filter", 0.0, 0.1):
        depth_m, flying = filter_depth(depth_m, params)
        with np.errstate(invalid="ignore"):
            filled = ~(np.asarray(depth_raw) > 0) & np.isfinite(depth_m)
    with _stage(progress, timings, "mesh", 0.1, 0.7):
        obj = object_mesh(dcam, depth_m, lo, hi, params.edge_angle_deg, rays_cam)
        if flying.any() and obj.in_roi is not None:
            # removed flying pixels inside the ROI stay "object area without a certain surface" (P5)
            obj.in_roi = obj.in_roi | _flying_in_roi(dcam, flying, depth_raw, lo, hi, rays_cam)
        obj = extend_boundary(obj, dcam, params.boundary_px, depth_m, flying=flying, depth_raw=depth_raw)
        obj_scene = MeshScene(obj.vertices, obj.triangles)
    with _stage(progress, timings, "uncertainty mesh", 0.7, 1.0):
        unc = uncertainty_mesh(obj, dcam.center_rig, float(hi[2]))
        unc_scene = MeshScene(unc.vertices, unc.triangles, skip_m=NEAR_CAMERA_M)  # see NEAR_CAMERA_M
    return Meshes(obj, unc, obj_scene, unc_scene, flying, filled)


def filter_depth(depth_m: np.ndarray, params: RegistrationParams) -> tuple[np.ndarray, np.ndarray]:
    """The ToF clean-up the parameters ask for: (cleaned depth (H, W) float32 metres, NaN = none;
    flying-pixel mask (H, W) bool)."""
    from .depthfilter import clean_depth

    return clean_depth(depth_m, params.flying_filter, params.flying_jump_rel, params.denoise,
                       params.denoise_size, params.denoise_tol_rel, params.flying_repair,
                       params.fill_holes)


def _flying_in_roi(dcam: Camera, flying: np.ndarray, depth_m: np.ndarray, lo: np.ndarray, hi: np.ndarray,
                   rays_cam: np.ndarray | None) -> np.ndarray:
    """(H, W) bool: flying pixels whose raw measurement lies inside the ROI."""
    idx = np.flatnonzero(flying)
    d = pixel_rays_cam(dcam)[idx] if rays_cam is None else rays_cam[idx]
    z = np.asarray(depth_m, dtype=np.float64).reshape(-1)[idx]
    X = dcam.to_rig(d.astype(np.float64) * z[:, None])
    out = np.zeros(flying.size, dtype=bool)
    with np.errstate(invalid="ignore"):
        out[idx] = np.all((X >= lo) & (X <= hi), axis=1)
    return out.reshape(flying.shape)


@contextmanager
def _stage(progress: Reporter, timings: dict[str, float], name: str, start: float, end: float) -> Iterator[None]:
    """Report ``name`` at ``start`` (a cancellation point), time it into ``timings``, report ``end``
    (:meth:`Reporter.stage`, the one timing mechanism, with this registration's own table)."""
    with progress.timed(timings).stage(name, start, end):
        yield


def _segment_dirs(origin: np.ndarray, points: np.ndarray, stop_before_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Directions (N, 3) float32 from ``origin`` (3,) towards ``points`` (N, 3), scaled so that
    t = 1 lies ``stop_before_m`` before each point; and a mask (N,) of usable segments."""
    vec = points.astype(np.float32) - origin.astype(np.float32)
    dist = np.sqrt(np.einsum("ij,ij->i", vec, vec))
    with np.errstate(divide="ignore", invalid="ignore"):
        scale = 1.0 - np.float32(stop_before_m) / dist
    usable = scale > 0
    vec *= np.where(usable, scale, 0)[:, None]
    return vec, usable


# ---------------------------------------------------------------------------- the registrar
class Registrar:
    """Holds the meshes and ray-casting scenes of one recording so that registering to another
    target reuses them. Build once per (rig, recording, params); call :meth:`register` per target.
    """

    def __init__(self, rig: Rig, recording: Recording, params: RegistrationParams | None = None):
        self.rig = rig
        self.recording = recording
        self.params = params or RegistrationParams()
        rig.depth()  # InputError if the rig has no depth camera
        recording.check(rig)
        self.meshes: Meshes | None = None
        self._rays_cam: dict[str, np.ndarray] = {}   # camera -> (H*W, 3) z=1 directions, camera frame
        self._grids: dict[str, RayGrid | None] = {}  # camera -> its undistortion grid (target rays)
        self._float_images: dict[str, np.ndarray] = {}
        self.timings: dict[str, float] = {}
        self.warnings: list[str] = []  # about the inputs, found while preparing (see core/roi.py)
        self._mixed_radius: dict[str, float] = {}  # source camera -> the mixed flag's radius, its px

    # -- caches
    def ray_cache(self) -> tuple[dict[str, np.ndarray], dict[str, RayGrid | None]]:
        """The pixel-ray caches (camera name -> rays, camera name -> undistortion grid), for
        :meth:`use_ray_cache` of another Registrar of the same rig (a batch: they depend on the
        cameras only)."""
        return self._rays_cam, self._grids

    def use_ray_cache(self, cache: tuple[dict[str, np.ndarray], dict[str, RayGrid | None]]) -> None:
        """Share the pixel rays of another Registrar of the *same rig* (see :meth:`ray_cache`)."""
        self._rays_cam, self._grids = cache

    def _camera_rays(self, cam: Camera) -> np.ndarray:
        if cam.name not in self._rays_cam:
            self._rays_cam[cam.name] = pixel_rays_cam(cam)
        return self._rays_cam[cam.name]

    def _target_rays(self, cam: Camera, cones: list[ConeMarks | None]) -> tuple[np.ndarray, np.ndarray]:
        """Flat indices (M,) of the target pixels whose rays can meet a mesh of ``cones``, and
        their unit rig-frame directions (M, 3) float32 (:func:`.raycast.pixel_rays_toward`);
        every other ray misses."""
        if cam.name not in self._grids:
            self._grids[cam.name] = ray_grid(cam)
        return pixel_rays_toward(cam, cones, self._grids[cam.name])

    def _mixed(self, scam: Camera, uvh: np.ndarray, case_h: np.ndarray, obj_idx: np.ndarray,
               shape: tuple[int, int]) -> np.ndarray:
        """(H, W) bool: P1 pixels whose footprint in ``scam`` reaches across a silhouette (core/mixed.py)."""
        from .mixed import calibration_residual_px, mixed_radius, silhouette_distance

        meshes = self.meshes
        assert meshes is not None
        out = np.zeros(shape[0] * shape[1], dtype=bool)
        r = mixed_radius(scam, self.params.mixed_radius_px, calibration_residual_px(self.rig.extra, scam.name))
        self._mixed_radius[scam.name] = r
        p1 = np.flatnonzero(case_h == CASE_P1)
        unc = meshes.uncertainty
        if r <= 0 or len(p1) == 0 or unc.n_triangles == 0:
            return out.reshape(shape)
        # the curtains' top edges are the object mesh's boundary edges (mesh.uncertainty_mesh)
        n_top, n_edges = unc.n_vertices // 2, unc.n_triangles // 2
        d = silhouette_distance(scam, unc.vertices[:n_top], unc.triangles[:n_edges, :2], meshes.object_scene,
                                uvh[p1], self.params.occlusion_tol_m, max_px=r)
        out[obj_idx[p1]] = d <= r
        return out.reshape(shape)

    @staticmethod
    def _depth_camera_hits(meshes: Meshes, N: int) -> tuple[np.ndarray, ...]:
        """Target rays of the depth camera itself, answered exactly instead of cast.

        Each of its pixel rays passes exactly through that pixel's mesh vertex, and the mesh is a
        height field over the depth image, so the first hit *is* the vertex; and the uncertainty
        mesh runs along these very rays, so nothing can lie in front of a vertex (no P3.1).
        Casting would be ill-conditioned here (rays through vertices and along curtain
        triangles are where ray tracers miss or graze). Pixels with a measurement inside the ROI
        that did not make it into the mesh (cut edges, flying pixels) are the depth camera's
        P5: object area without a certain surface.
        """
        obj = meshes.object
        sample = obj.pixel >= 0  # not the skirt
        obj_idx = obj.pixel[sample].astype(np.int64)
        points = np.full((N, 3), np.nan, dtype=np.float32)
        points[obj_idx] = obj.vertices[sample]
        has = np.zeros(N, dtype=bool)
        has[obj_idx] = True
        no_idx = np.flatnonzero(~has)
        in_roi = obj.in_roi.reshape(-1) if obj.in_roi is not None else np.zeros(N, dtype=bool)
        return obj_idx, points, np.zeros(len(obj_idx), dtype=bool), no_idx, in_roi[no_idx]

    def prepare(self, progress: Reporter | None = None) -> None:
        """Build object mesh, uncertainty mesh and Open3D scenes (idempotent)."""
        if self.meshes is not None:
            return
        progress = ensure_reporter(progress)
        dcam = self.rig.depth()
        depth_m = self.recording.depth_m(self.rig.depth_scale)
        with _stage(progress, self.timings, "depth rays", 0.0, 0.2):
            rays = self._camera_rays(dcam)
        self.meshes = build_meshes(self.rig, depth_m, self.params, rays, progress.sub(0.2, 1.0), self.timings)
        from .roi import cut_warning  # an ROI that cuts off most of the plant looks complete otherwise

        w = cut_warning(dcam.to_rig(rays * depth_m.reshape(-1, 1)), *self.params.roi(self.rig))
        self.warnings = [w] if w else []
        if self.meshes.object.n_triangles == 0:
            raise InputError(
                "no surface inside the region of interest: the depth map has no valid neighbouring "
                f"pixels within roi {self.params.roi(self.rig)[0].tolist()} .. {self.params.roi(self.rig)[1].tolist()}",
                self.recording.paths.get("depth", self.recording.folder),
            )

    def register(self, target: str, progress: Reporter | None = None,
                 on_image: Callable[[str, Any], None] | None = None) -> RegistrationResult:
        """Register every camera into ``target``'s view (module docstring).

        ``on_image(camera, image)``, if given, is called as soon as a camera's registered image
        (the ``registered[camera]`` of the result, not to be changed) is complete, on this thread,
        so that a caller can start writing it while the other sources are still being registered
        (``plantreg register`` encodes the TIFFs early: :class:`~.export.EarlyTiffs`).
        Sources with more channels are registered first (a cube's TIFF is the longest to write);
        the result's dicts keep the rig's camera order.
        """
        progress = ensure_reporter(progress)
        tcam = self.rig.camera(target)
        timings: dict[str, float] = {}
        t_start = time.perf_counter()
        built = self.meshes is None
        before = dict(self.timings)
        self.prepare(progress.sub(0.0, 0.15))
        if built:
            for k, v in self.timings.items():
                timings[k] = v - before.get(k, 0.0)
        meshes = self.meshes
        assert meshes is not None
        p = self.params
        H, W = tcam.shape
        N = H * W
        o_t = tcam.center_rig

        # ---- target rays, cast once for all sources
        with _stage(progress, timings, "target rays", 0.15, 0.3):
            if target == self.rig.depth_camera:
                obj_idx, points, p31, no_idx, p5 = self._depth_camera_hits(meshes, N)
            else:
                # only the pixels whose rays can reach a mesh get rays (a 4K view: a fraction of
                # 8.3 M), and of those only the rays that can are cast
                cone_o, cone_u = (cone_marks(o_t, tcam.R_cam_rig, m.vertices, m.triangles)
                                  for m in (meshes.object, meshes.uncertainty))
                pix, dirs = self._target_rays(tcam, [cone_o, cone_u])
                may = None if cone_o is None else cone_o.rays_may_hit(dirs)
                hits = cast_where(meshes.object_scene, o_t, dirs, may, check=progress.check)
                hit = np.flatnonzero(hits.hit)
                obj_idx = pix[hit]
                t_obj = hits.t[hit]
                points = np.full((N, 3), np.nan, dtype=np.float32)
                points[obj_idx] = o_t.astype(np.float32) + dirs[hit] * t_obj[:, None]
                # uncertainty mesh before the object hit (P3.1) / anywhere (P5 when no object hit)
                seg = dirs[hit] * np.maximum(t_obj - np.float32(p.uncertainty_tol_m), 0)[:, None]
                p31 = meshes.uncertainty_scene.occluded(o_t, seg, 1.0, check=progress.check)
                miss = np.flatnonzero(~hits.hit)
                no_idx = pix[miss]  # the pixels without an object hit that P5 can concern
                may_u = None if cone_u is None else cone_u.rays_may_hit(dirs)
                p5 = np.zeros(len(no_idx), dtype=bool)
                test = np.arange(len(no_idx)) if may_u is None else np.flatnonzero(may_u[miss])
                p5[test] = meshes.uncertainty_scene.occluded(o_t, dirs[miss[test]], np.inf, check=progress.check)
            area = np.full(N, AREA_P6, dtype=np.uint8)
            area[obj_idx] = np.where(p31, AREA_P5, AREA_P4)
            area[no_idx[p5]] = AREA_P5
            base = np.full(N, CASE_BACKGROUND, dtype=np.uint8)
            base[no_idx[p5]] = CASE_P5
            base[obj_idx] = np.where(p31, CASE_P31, CASE_P1)

        images = self.recording.images
        cams = [c for c in self.rig.cameras if c.name != target]
        rig_order = [c.name for c in cams]
        cams.sort(key=lambda c: -_channels(images.get(c.name)))  # stable: rig order among equals
        registered: dict[str, np.ndarray] = {}
        source_uv: dict[str, np.ndarray] = {}
        cases: dict[str, np.ndarray] = {}
        mixed: dict[str, np.ndarray] = {}
        Xh = points[obj_idx]

        # the target itself: its own pixel, its own raw value
        if target in images:
            with _stage(progress, timings, f"sampling {target}", 0.3, 0.32):
                uv = np.full((N, 2), np.nan, dtype=np.float32)
                uv[obj_idx, 0] = obj_idx % W
                uv[obj_idx, 1] = obj_idx // W
                source_uv[target] = uv.reshape(H, W, 2)
                img = images[target]
                C = 1 if img.ndim == 2 else int(np.prod(img.shape[2:]))
                vals = img.reshape(N, C)[obj_idx].astype(np.float32)
                registered[target] = _registered_image(obj_idx, vals, H, W, img)
                if on_image is not None:
                    on_image(target, registered[target])

        n = max(1, len(cams))
        for i, scam in enumerate(cams):
            a = 0.32 + 0.68 * i / n
            b = 0.32 + 0.68 * (i + 1) / n
            with _stage(progress, timings, f"classification {scam.name}", a, a + 0.45 * (b - a)):
                uvh, z = project_points(scam, Xh)
                inside = (z > 0) & scam.in_image(uvh)
                in_idx = np.flatnonzero(inside)
                C_s = scam.center_rig
                seg, usable = _segment_dirs(C_s, Xh[in_idx], p.occlusion_tol_m)
                occ = np.zeros(len(in_idx), dtype=bool)
                occ[usable] = meshes.object_scene.occluded(C_s, seg[usable], 1.0, check=progress.check)
                # P3.2 only matters where neither P2 nor P3.1 already decides the case
                need = np.flatnonzero(~occ & ~p31[in_idx])
                seg_u, usable_u = _segment_dirs(C_s, Xh[in_idx[need]], p.uncertainty_tol_m)
                unc = np.zeros(len(in_idx), dtype=bool)
                unc[need[usable_u]] = meshes.uncertainty_scene.occluded(C_s, seg_u[usable_u], 1.0,
                                                                         check=progress.check)
                case_h = base[obj_idx].copy()  # 1 or 3 (P3.1)
                ci = case_h[in_idx]
                ci[unc] = CASE_P32
                ci[occ] = CASE_P2
                case_h[in_idx] = ci
                case_h[~inside] = CASE_OUTSIDE
                cs = base.copy()
                cs[obj_idx] = case_h
                cases[scam.name] = cs.reshape(H, W)
                uv = np.full((N, 2), np.nan, dtype=np.float32)
                uv[obj_idx] = uvh
                source_uv[scam.name] = uv.reshape(H, W, 2)
            with _stage(progress, timings, f"mixed {scam.name}", a + 0.45 * (b - a), a + 0.5 * (b - a)):
                mixed[scam.name] = self._mixed(scam, uvh, case_h, obj_idx, (H, W))
            if scam.name in images:
                with _stage(progress, timings, f"sampling {scam.name}", a + 0.5 * (b - a), b):
                    img = images[scam.name]
                    C = 1 if img.ndim == 2 else int(np.prod(img.shape[2:]))
                    # at the hits only; sample_bilinear writes NaN only where no sample goes (a
                    # full NaN pass first cost ~0.5 s for the 1 GB of a 204-band cube in a 4K view)
                    vals = np.empty((len(obj_idx), C), dtype=np.float32)
                    sub = progress.sub(a + 0.5 * (b - a), b)
                    if on_image is not None and keep_at_hits(H, W, C):
                        # a cube kept at its hits is handed over before it is sampled: its TIFF
                        # is encoded on the other core while the values are filled in, tile rows
                        # as soon as they are final (HitImage.ready); one sampling thread then
                        registered[scam.name] = _streamed_hits(obj_idx, vals, H, W, img, on_image, scam.name,
                                                               lambda done: sample_bilinear(
                                                                   img, uvh[in_idx], sub, out=vals, rows=in_idx,
                                                                   done=done, threads=1))
                    else:
                        sample_bilinear(img, uvh[in_idx], sub, out=vals, rows=in_idx)
                        registered[scam.name] = _registered_image(obj_idx, vals, H, W, img)
                        if on_image is not None:
                            on_image(scam.name, registered[scam.name])

        timings["total"] = time.perf_counter() - t_start
        # the rig's camera order again (the outputs list cameras in it)
        registered = {c: registered[c] for c in [target, *rig_order] if c in registered}
        source_uv = {c: source_uv[c] for c in [target, *rig_order] if c in source_uv}
        cases, mixed = ({c: d[c] for c in rig_order if c in d} for d in (cases, mixed))
        stats = {
            "object_mesh": {"vertices": meshes.object.n_vertices, "triangles": meshes.object.n_triangles},
            "uncertainty_mesh": {"vertices": meshes.uncertainty.n_vertices,
                                 "triangles": meshes.uncertainty.n_triangles},
            "target_pixels": int(N),
            "object_hits": int(len(obj_idx)),
            "flying_pixels": int(meshes.flying.sum()) if meshes.flying is not None else 0,
            "filled_pixels": int(meshes.filled.sum()) if meshes.filled is not None else 0,
            "mixed_pixels": {cam: int(m.sum()) for cam, m in mixed.items()},
            "mixed_radius_px": {cam: round(self._mixed_radius.get(cam, 0.0), 3) for cam in mixed},
        }
        progress(1.0, "done")
        return RegistrationResult(
            target=target,
            points_rig=points.reshape(H, W, 3),
            area=area.reshape(H, W),
            registered=registered,
            source_uv=source_uv,
            cases=cases,
            params=p,
            timings=timings,
            stats=stats,
            flying=meshes.flying,
            mixed=mixed,
            warnings=list(self.warnings),
        )


#: Registered images larger than this (dense, bytes) are kept as :class:`~.hits.HitImage`
#: (values at the object hits only, expanded on demand): a 204-band cube in a 4K view is 6.8 GB
#: dense, ~0.8 GB at the hits. Smaller ones stay plain arrays.
DENSE_LIMIT_BYTES = 1 << 30
#: Cubes (more than 4 bands) are kept at the hits already above this size, in views of at most
#: :data:`CUBE_HITS_MAX_PIXELS` pixels: the 204-band cube in the 640x576 infrared view is 300 MB
#: dense, 88 % NaN -- filling it, scanning its tiles for NaN when writing and its rows when
#: rendering cost ~0.5 s CPU of a 3.5 s `plantreg register`. Up to that many pixels a preview
#: takes its statistics from every pixel, so the hits-only preview is the dense one bit for bit
#: (core.display: ``_MAX_SAMPLES``); above it, the (strided) statistics may pick other pixels.
CUBE_HITS_BYTES = 64 << 20
CUBE_HITS_MAX_PIXELS = 1_000_000


def _channels(img: np.ndarray | None) -> int:
    """Channels of a raw image (H, W[, C...]); 0 for none."""
    if img is None:
        return 0
    return 1 if img.ndim == 2 else int(np.prod(img.shape[2:]))


def keep_at_hits(H: int, W: int, C: int) -> bool:
    """Whether a registered image (H, W, C) float32 is kept as a :class:`~.hits.HitImage`."""
    dense = H * W * C * 4
    return dense > DENSE_LIMIT_BYTES or (C > 4 and dense > CUBE_HITS_BYTES and H * W <= CUBE_HITS_MAX_PIXELS)


def _registered_image(obj_idx: np.ndarray, vals: np.ndarray, H: int, W: int, img: np.ndarray):
    """Values (M, C) float32 at the target pixels ``obj_idx`` (M,) -> the registered image:
    (H, W[, C]) float32, NaN elsewhere, or the same as a HitImage (:func:`keep_at_hits`)."""
    C = vals.shape[1]
    shape = (H, W) if img.ndim == 2 or C == 1 else (H, W, C)
    if keep_at_hits(H, W, C):
        from .hits import HitImage

        return HitImage(obj_idx, vals, shape)
    dense = nan_array((H * W, C))
    dense[obj_idx] = vals
    return _shape_values(dense, H, W, img)


def _streamed_hits(obj_idx: np.ndarray, vals: np.ndarray, H: int, W: int, img: np.ndarray,
                   on_image: Callable[[str, Any], None], cam: str, fill: Callable[[Callable[[int], None]], Any]):
    """The HitImage of ``vals`` (M, C) at ``obj_idx``, given to ``on_image`` *before* ``fill(done)``
    writes its values (``done(k)``: the first k rows are final); its ``block`` waits for them."""
    from .hits import HitImage, RowsReady

    C = vals.shape[1]
    out = HitImage(obj_idx, vals, (H, W) if img.ndim == 2 or C == 1 else (H, W, C))
    assert np.may_share_memory(out.values, vals)  # obj_idx is ascending: no reordering copy
    out.ready = RowsReady()
    on_image(cam, out)
    try:
        fill(out.ready.set)
    except BaseException:
        out.ready.fail()  # a waiting reader stops (Cancelled) instead of waiting for ever
        raise
    out.ready = None
    return out


def _shape_values(vals: np.ndarray, H: int, W: int, img: np.ndarray) -> np.ndarray:
    """(N, C) -> (H, W) for single-channel sources, else (H, W, C)."""
    C = vals.shape[1]
    if img.ndim == 2 or C == 1:
        return vals.reshape(H, W)
    return vals.reshape(H, W, C)


def register(rig: Rig, recording: Recording, target: str, params: RegistrationParams | None = None,
             progress: Reporter | None = None) -> RegistrationResult:
    """One-shot convenience: ``Registrar(rig, recording, params).register(target, progress)``."""
    return Registrar(rig, recording, params).register(target, progress)


# ---------------------------------------------------------------------------- pixel transport
_MESH_CACHE: dict[tuple, Meshes] = {}


def _mesh_key(rig: Rig, depth_m: np.ndarray, params: RegistrationParams) -> tuple:
    dcam = rig.depth()
    lo, hi = params.roi(rig)
    h = hashlib.blake2b(np.ascontiguousarray(depth_m, dtype=np.float32).tobytes(), digest_size=16).hexdigest()
    geom = np.concatenate([dcam.K.ravel(), dcam.dist, dcam.R_cam_rig.ravel(), dcam.t_cam_rig, lo, hi,
                           [params.edge_angle_deg, params.boundary_px, dcam.width, dcam.height,
                            params.flying_filter, params.flying_jump_rel, params.denoise, params.denoise_size,
                            params.denoise_tol_rel, params.flying_repair, params.fill_holes]])
    return (h, geom.tobytes())


def transport_pixels(rig: Rig, depth_m: np.ndarray, origin: str, uv: np.ndarray, target: str,
                     params: RegistrationParams | None = None) -> np.ndarray:
    """Carry pixels (N, 2) of camera `origin` through the mesh of depth map `depth_m` (H, W metres, NaN = none) into camera `target`:
    cast the origin's rays (through its distortion) into the object mesh, project the hits into target. Returns (N, 2), NaN where no hit.
    Exactly the registration code path (same mesh builder, same ray caster).

    Hits behind the target camera are NaN; positions outside the target image are returned as
    they are (callers decide). The meshes of the last few depth maps are cached.
    """
    params = params or RegistrationParams()
    depth_m = np.asarray(depth_m, dtype=np.float32)
    key = _mesh_key(rig, depth_m, params)
    meshes = _MESH_CACHE.get(key)
    if meshes is None:
        meshes = build_meshes(rig, depth_m, params)
        if len(_MESH_CACHE) >= 4:
            _MESH_CACHE.pop(next(iter(_MESH_CACHE)))
        _MESH_CACHE[key] = meshes
    ocam, tcam = rig.camera(origin), rig.camera(target)
    uv = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
    out = np.full((len(uv), 2), np.nan)
    ok = np.flatnonzero(np.isfinite(uv).all(axis=1))
    if len(ok) == 0:
        return out
    o, d = ocam.rays_rig(uv[ok])
    d = d.astype(np.float32)
    hits = meshes.object_scene.cast(o, d)
    t = hits.t.copy()
    # A ray through a mesh vertex (e.g. an integer pixel of the depth camera itself, whose
    # pixel centres *are* the vertices) is where ray tracers let rays slip through. Retry the
    # misses nudged by 1e-3 px in four directions and keep the nearest hit.
    miss = np.flatnonzero(~np.isfinite(t))
    if len(miss):
        eps = 1e-3
        for du, dv in ((eps, 0), (-eps, 0), (0, eps), (0, -eps)):
            _o, dn = ocam.rays_rig(uv[ok][miss] + (du, dv))
            tn = meshes.object_scene.cast(o, dn.astype(np.float32)).t
            t[miss] = np.minimum(t[miss], tn)
    hit = np.isfinite(t)
    X = o.astype(np.float32) + d[hit] * t[hit][:, None]
    uvt, _z = project_points(tcam, X)
    out[ok[hit]] = uvt
    return out
