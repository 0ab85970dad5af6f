"""Mixed-pixel flag: registered values whose source footprint reaches across a silhouette.

A source pixel integrates light from its footprint, widened by the lens's blur, and the
registered value is interpolated from the source pixels around the projected point. Where that
neighbourhood reaches across a silhouette of the object (a leaf's outline against the soil, or
an upper leaf's edge over a lower one), the value mixes two surfaces -- a leaf edge in the
thermal image carries part of the soil's temperature -- even though the point itself is
legitimately seen (P1).

Geometry. The silhouettes a source camera can see are the boundary edges of the object mesh
(its outline and the cut lines at depth jumps, with the boundary skirt: exactly the top edges of
the uncertainty mesh's curtains) whose ends are visible from the source (a segment from the
source centre to the end meets no object surface more than ``occlusion_tol_m`` before it).
They are projected through the source's distortion model and drawn into a mask of the source
image; the distance of every P1 point's projection (rounded to the pixel grid) to the nearest
drawn silhouette pixel (exact Euclidean distance, looked up at the few pixel offsets within the
radius: within about half a source pixel, as lines are drawn on the pixel grid) is compared with the
radius

    r = ``mixed_radius_px`` (default 1: the pixel's own half width plus the half pixel that
        bilinear interpolation reaches into the neighbours) + 2 x ``blur_px`` + ``registration_px``

where ``blur_px`` is an optional key of the camera in the rig: the Gaussian sigma of its optical
blur in its own pixels (2 sigma hold 95 % of the blur's weight), and ``registration_px`` how far
off, in its pixels, the mapping into the camera may be (the calibration's uncertainty: a point
projected 3 px beside where the camera really saw it reads the soil beside a leaf rim even with a
sharp lens). ``registration_px`` is a camera key too; without it, a rig fitted from landmarks
(``plantreg fit-rig`` in every variant, the landmark page) supplies it from its calibration record
(``core/camera/record.py``: the larger of the camera's fitted and leave-one-out median landmark
residual; for older records the fitted median), and any other rig 0. Points within ``r`` are flagged.

What it does not catch: silhouettes the depth camera did not measure (a surface it could not see
at all, thin structures below its resolution, a leaf's fold turning away from the source inside
one smooth mesh surface), mixing through translucency or reflections, any blur wider than
the stated ``blur_px``, and calibration errors larger than ``registration_px``. It flags
conservatively near cut lines of steep surfaces that are not real edges.
"""

from __future__ import annotations

import numpy as np

from ..camera.camera import Camera
from ..camera.record import CalibrationRecord
from ..geometry.raycast import MeshScene, segment_dirs


def _px_key(cam: Camera, key: str, default: float = 0.0) -> float:
    try:
        v = float(cam.extra.get(key, default) or 0.0)
    except (TypeError, ValueError):
        v = 0.0
    return max(v, 0.0) if np.isfinite(v) else 0.0


def calibration_residual_px(rig_extra: dict, camera: str) -> float:
    """How far off, in ``camera``'s pixels, a rig fitted to landmarks may map into it (its
    calibration record's :meth:`~..camera.record.CalibrationRecord.registration_px`, whichever way
    the rig was fitted: ``fit-rig``, ``--refine``, ``--silhouette``, the landmark page, a nudge);
    0 for any other rig or a camera not fitted."""
    rec = CalibrationRecord.of(rig_extra)
    return rec.registration_px(camera) if rec is not None else 0.0


def mixed_radius(cam: Camera, base_px: float, registration_px: float = 0.0) -> float:
    """The flag's radius in ``cam``'s pixels: ``base_px`` + 2 x the camera's ``blur_px`` + its
    ``registration_px`` (rig keys of the camera; ``registration_px`` defaults to the argument,
    e.g. :func:`calibration_residual_px`)."""
    return float(base_px) + 2.0 * _px_key(cam, "blur_px") + _px_key(cam, "registration_px", registration_px)


def silhouette_distance(cam: Camera, top_vertices: np.ndarray, edges: np.ndarray, object_scene: MeshScene,
                        uv: np.ndarray, occlusion_tol_m: float = 0.002, max_px: float = 8.0) -> np.ndarray:
    """Distance (N,) float32 in source pixels from the points ``uv`` (N, 2) of source camera ``cam``
    to the nearest silhouette the source sees (inf beyond ``max_px`` or with none).

    ``top_vertices`` (V, 3) rig frame and ``edges`` (E, 2) int: the object mesh's boundary edges;
    ``object_scene``: the object mesh, for the visibility of their ends.
    """
    import cv2

    uv = np.asarray(uv, dtype=np.float32).reshape(-1, 2)
    out = np.full(len(uv), np.inf, dtype=np.float32)
    if len(uv) == 0 or len(edges) == 0:
        return out
    C = cam.center_rig
    used = np.unique(edges)
    seg, usable = segment_dirs(C, top_vertices[used], occlusion_tol_m)
    vis = np.zeros(len(top_vertices), dtype=bool)
    hidden = np.ones(len(used), dtype=bool)
    hidden[usable] = object_scene.occluded(C, seg[usable], 1.0)
    vis[used] = ~hidden
    keep = vis[edges[:, 0]] | vis[edges[:, 1]]  # an edge half hidden still shows its visible part
    if not keep.any():
        return out
    e = edges[keep]
    pv, z = cam.project(top_vertices.astype(np.float64))
    ok = np.isfinite(pv).all(axis=1) & (z > 0)
    e = e[ok[e[:, 0]] & ok[e[:, 1]]]
    # work in the bounding box of the query points (a 4K source stays cheap)
    pad = int(np.ceil(max_px)) + 2
    u, v = uv[:, 0], uv[:, 1]
    fin = np.isfinite(u) & np.isfinite(v)  # (column-wise: reductions along a length-2 axis are slow)
    if not fin.any() or len(e) == 0:
        return out
    uf, vf = u[fin], v[fin]
    lo = np.maximum(np.floor([uf.min(), vf.min()]).astype(int) - pad, 0)
    hi = np.minimum(np.ceil([uf.max(), vf.max()]).astype(int) + pad + 1, [cam.width, cam.height])
    w, h = int(hi[0] - lo[0]), int(hi[1] - lo[1])
    if w <= 0 or h <= 0:
        return out
    shift = 3  # sub-pixel line ends (1/8 px)
    ends = np.round((pv[e] - lo) * (1 << shift)).astype(np.int64)  # (E', 2, 2)
    far = np.abs(ends).max(axis=(1, 2)) > (1 << (shift + 20))  # projections far outside: not drawable
    ends = ends[~far].astype(np.int32)
    mask = np.zeros((h, w), dtype=np.uint8)
    cv2.polylines(mask, list(ends.reshape(-1, 2, 1, 2)), False, 1, 1, cv2.LINE_8, shift)
    # distances only matter up to max_px: look the drawn pixels up at the offsets within it
    # (5 offsets for 1 px, 29 for 3 px) instead of a distance transform of the whole box
    k = int(np.floor(max_px))
    ov, ou = np.mgrid[-k:k + 1, -k:k + 1]
    od = np.hypot(ou, ov).ravel()
    sel = od <= max_px
    order = np.argsort(od[sel], kind="stable")
    ou, ov, od = ou.ravel()[sel][order], ov.ravel()[sel][order], od[sel][order].astype(np.float32)
    qu = np.rint(uf - lo[0]).astype(np.int64)
    qv = np.rint(vf - lo[1]).astype(np.int64)
    flat = np.pad(mask, k, constant_values=0).reshape(-1)
    qi = np.flatnonzero((qu >= 0) & (qu < w) & (qv >= 0) & (qv < h))
    base = (qv[qi] + k) * (w + 2 * k) + (qu[qi] + k)
    d = np.full(len(qu), np.inf, dtype=np.float32)
    dq = np.full(len(qi), np.inf, dtype=np.float32)
    todo = np.arange(len(qi))
    for du, dv, dd in zip(ou, ov, od):  # nearest offsets first: each point is settled by its first hit
        hit = flat[base[todo] + dv * (w + 2 * k) + du] != 0
        dq[todo[hit]] = dd
        todo = todo[~hit]
        if len(todo) == 0:
            break
    d[qi] = dq
    out[fin] = d
    return out
