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

import time
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any, Callable, Iterator

import numpy as np

from ..camera.camera import Camera
from .cases import Area, Case
from ..errors import InputError
from ..geometry.mesh import TriMesh, extend_boundary, object_mesh, uncertainty_mesh
from ..progress import Reporter, ensure_reporter
from ..geometry.raycast import (NEAR_CAMERA_M, ConeMarks, MeshScene, RayGrid, cast_where, cone_marks,
                      pixel_rays_cam, pixel_rays_toward, ray_grid, segment_dirs)
from .hits import HitImage, RowsReady, nan_array
from .params import RegistrationParams, RegistrationResult
from .sampling import sample_bilinear
from ..data.recording import Recording
from ..camera.rig import Rig



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
    from ..geometry.depthfilter import clean_depth

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
        self.warnings: list[str] = []  # about the inputs, found while preparing (see core/geometry/roi.py)
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
        """(H, W) bool: P1 pixels whose footprint in ``scam`` reaches across a silhouette (core/registration/mixed.py)."""
        from .mixed import calibration_residual_px, mixed_radius, silhouette_distance

        meshes = self.meshes
        assert meshes is not None
        out = np.zeros(shape[0] * shape[1], dtype=bool)
        r = mixed_radius(scam, self.params.mixed_radius_px, calibration_residual_px(self.rig.extra, scam.name))
        self._mixed_radius[scam.name] = r
        p1 = np.flatnonzero(case_h == Case.P1)
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
        # an ROI that cuts off most of the plant, or takes in the ground, looks complete otherwise
        from ..geometry.roi import cut_warning, ground_warning

        X_rig = dcam.to_rig(rays * depth_m.reshape(-1, 1))
        roi = self.params.roi(self.rig)
        self.warnings = [w for w in (cut_warning(X_rig, *roi), ground_warning(X_rig, *roi)) if w]
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
            area = np.full(N, Area.P6, dtype=np.uint8)
            area[obj_idx] = np.where(p31, Area.P5, Area.P4)
            area[no_idx[p5]] = Area.P5
            base = np.full(N, Case.BACKGROUND, dtype=np.uint8)
            base[no_idx[p5]] = Case.P5
            base[obj_idx] = np.where(p31, Case.P31, Case.P1)

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
                uvh, z = scam.project(Xh)
                inside = (z > 0) & scam.in_image(uvh)
                in_idx = np.flatnonzero(inside)
                C_s = scam.center_rig
                seg, usable = segment_dirs(C_s, Xh[in_idx], p.occlusion_tol_m)
                occ = np.zeros(len(in_idx), dtype=bool)
                occ[usable] = meshes.object_scene.occluded(C_s, seg[usable], 1.0, check=progress.check)
                # P3.2 only matters where neither P2 nor P3.1 already decides the case
                need = np.flatnonzero(~occ & ~p31[in_idx])
                seg_u, usable_u = segment_dirs(C_s, Xh[in_idx[need]], p.uncertainty_tol_m)
                unc = np.zeros(len(in_idx), dtype=bool)
                unc[need[usable_u]] = meshes.uncertainty_scene.occluded(C_s, seg_u[usable_u], 1.0,
                                                                         check=progress.check)
                case_h = base[obj_idx].copy()  # 1 or 3 (P3.1)
                ci = case_h[in_idx]
                ci[unc] = Case.P32
                ci[occ] = Case.P2
                case_h[in_idx] = ci
                case_h[~inside] = Case.OUTSIDE
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
                    # full NaN pass first is a pass over the 1 GB of a 204-band cube in a 4K view)
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
#: rendering were a large share of a `plantreg register`'s CPU. Up to that many pixels a preview
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
        return HitImage(obj_idx, vals, shape)
    dense = nan_array((H * W, C))
    dense[obj_idx] = vals
    return _shape_values(dense, H, W, img)


def _streamed_hits(obj_idx: np.ndarray, vals: np.ndarray, H: int, W: int, img: np.ndarray,
                   on_image: Callable[[str, Any], None], cam: str, fill: Callable[[Callable[[int], None]], Any]):
    """The HitImage of ``vals`` (M, C) at ``obj_idx``, given to ``on_image`` *before* ``fill(done)``
    writes its values (``done(k)``: the first k rows are final); its ``block`` waits for them."""
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
