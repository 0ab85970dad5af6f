"""Carrying single pixels of one camera into another through a depth map's object mesh
(calibration's error tables, rig refinement): exactly the registration's code path."""

from __future__ import annotations

import hashlib
import threading

import numpy as np

from ..camera.rig import Rig
from .params import RegistrationParams
from .register import Meshes, build_meshes

#: The meshes of the last few depth maps (callers on several threads: the lock guards it).
_MESH_CACHE: dict[tuple, Meshes] = {}
_MESH_LOCK = threading.Lock()


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
    with _MESH_LOCK:
        meshes = _MESH_CACHE.get(key)
    if meshes is None:
        meshes = build_meshes(rig, depth_m, params)
        with _MESH_LOCK:
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
    uvt, _z = tcam.project(X)
    out[ok[hit]] = uvt
    return out
