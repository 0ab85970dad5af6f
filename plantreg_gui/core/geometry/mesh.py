"""Object mesh from a depth map, and the uncertainty mesh around it.

Object mesh
-----------
1. Back-projection: every depth pixel centre (u, v) with depth d (metres along the depth
   camera's optical axis, i.e. camera-frame z) becomes ``X_cam = d * (x, y, 1)`` where (x, y)
   are the pixel's *undistorted* normalised coordinates (the depth camera's intrinsics and
   distortion), then ``X_rig`` via the depth camera's pose (identity for the usual rig whose
   frame is the depth camera's).
2. ROI crop: points outside the box ``roi_min <= X_rig <= roi_max`` are dropped; since the
   box's max z is the ground plane, the ground is not part of the object.
3. 8-neighbourhood triangulation: each 2x2 block of neighbouring pixels a b / c d is split into
   two triangles along one of its diagonals (a-d or b-c). The split that keeps more valid
   triangles wins; on a tie the shorter 3D diagonal (the better approximation of the surface).
4. Edge cut (the paper's angle criterion): an edge between neighbouring points P, Q is cut when
   the angle between the edge direction ``Q - P`` and the depth camera's viewing ray through the
   edge midpoint ``(P + Q) / 2`` is below ``edge_angle_deg`` (default 15 degrees). A surface
   seen by the depth camera has its neighbouring samples roughly across the line of sight; an
   edge running nearly *along* the line of sight joins samples of different surfaces (a jump in
   depth), so it is not a surface. Triangles with a cut edge are dropped. A plane inclined
   60 degrees to the image plane meets the line of sight at ~30 degrees and stays whole; a 5 cm
   step between leaves at 1 m (samples ~2 mm apart) meets it at ~2 degrees and is cut.

5. Boundary skirt (:func:`extend_boundary`, ``boundary_px`` = 0.5): a mesh through pixel
   centres stops half a pixel short of what its boundary pixels saw. Boundary vertices get an
   outer copy half a pixel further out in the depth image (at their own depth), so that
   silhouettes sit where they most likely are instead of systematically inside. Not at holes
   that noise cuts into a smooth surface (depth jump across the edge <= 1 cm).

Uncertainty mesh
----------------
Boundary edges of the (extended) object mesh (edges of exactly one triangle: the silhouette and the cut
lines) extruded along the depth camera's rays -- from the camera centre through each boundary
vertex -- down to the ground plane z = ``ground_z``: two triangles per edge. It encloses the
space behind the measured surface that the depth camera cannot see.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..camera.camera import Camera


@dataclass
class TriMesh:
    """``vertices`` (V, 3) float32 in the rig frame, ``triangles`` (F, 3) int32.

    ``pixel`` (V,) int32: for an object mesh, the flat index (row * W + col) of the depth pixel
    each vertex came from; -1 for vertices that are not depth samples (uncertainty mesh floor).
    ``in_roi`` (H, W) bool, object mesh only: depth pixels with a measurement inside the ROI
    (meshed or not).
    """

    vertices: np.ndarray
    triangles: np.ndarray
    pixel: np.ndarray | None = None
    in_roi: np.ndarray | None = None

    @property
    def n_vertices(self) -> int:
        return int(len(self.vertices))

    @property
    def n_triangles(self) -> int:
        return int(len(self.triangles))

    @classmethod
    def empty(cls) -> "TriMesh":
        return cls(*_empty_arrays())

    def to_open3d(self):  # pragma: no cover - convenience for users
        import open3d as o3d

        m = o3d.geometry.TriangleMesh()
        m.vertices = o3d.utility.Vector3dVector(self.vertices.astype(np.float64))
        m.triangles = o3d.utility.Vector3iVector(self.triangles)
        return m


def backproject_depth(depth_cam: Camera, depth_m: np.ndarray, rays_cam: np.ndarray | None = None) -> np.ndarray:
    """Depth map (H, W) metres (NaN/0 = none) -> rig-frame points (H, W, 3) float32, NaN where none.

    ``rays_cam`` (H*W, 3): the depth camera's z=1 pixel directions, if already computed.
    """
    from .raycast import pixel_rays_cam

    H, W = depth_cam.shape
    depth_m = np.asarray(depth_m, dtype=np.float32)
    if depth_m.shape != (H, W):
        raise ValueError(f"depth map is {depth_m.shape[1]}x{depth_m.shape[0]}, depth camera is {W}x{H}")
    d = pixel_rays_cam(depth_cam) if rays_cam is None else rays_cam
    z = depth_m.reshape(-1).copy()
    z[~(z > 0)] = np.nan
    P = d.astype(np.float32) * z[:, None]
    R, t = depth_cam.R_cam_rig, depth_cam.t_cam_rig
    if not (np.allclose(R, np.eye(3)) and np.allclose(t, 0)):
        P = ((P.astype(np.float64) - t) @ R).astype(np.float32)  # X_rig = R^T (X_cam - t)
    return P.reshape(H, W, 3)


def _keep_edges(P: np.ndarray, Q: np.ndarray, center: np.ndarray, cos2_max: float) -> np.ndarray:
    """(…) bool: both ends valid and the edge P-Q is not within the cut angle of the line of sight.

    ``P``, ``Q`` (..., 3); ``center`` (3,) the depth camera centre; ``cos2_max`` = cos^2(angle).
    """
    e = Q - P
    r = (P + Q) * 0.5 - center
    er = np.einsum("...k,...k->...", e, r)
    ee = np.einsum("...k,...k->...", e, e)
    rr = np.einsum("...k,...k->...", r, r)
    with np.errstate(invalid="ignore"):
        # angle >= threshold  <=>  cos^2 <= cos^2(threshold); NaN (missing end) compares False
        return (er * er <= cos2_max * ee * rr) & (ee > 0)


def object_mesh(depth_cam: Camera, depth_m: np.ndarray, roi_min: np.ndarray, roi_max: np.ndarray,
                edge_angle_deg: float = 15.0, rays_cam: np.ndarray | None = None) -> TriMesh:
    """Triangle mesh of the measured surface (see the module docstring for the method).

    ``depth_m`` (H, W) metres, NaN or <= 0 = no measurement; ``roi_min``/``roi_max`` (3,) rig frame.
    """
    H, W = depth_cam.shape
    P = backproject_depth(depth_cam, depth_m, rays_cam)
    lo = np.asarray(roi_min, dtype=np.float32)
    hi = np.asarray(roi_max, dtype=np.float32)
    with np.errstate(invalid="ignore"):
        valid = np.all((P >= lo) & (P <= hi), axis=2)
    P = np.where(valid[..., None], P, np.float32(np.nan))
    if H < 2 or W < 2 or not valid.any():
        return TriMesh(*_empty_arrays(), in_roi=valid)
    center = depth_cam.center_rig.astype(np.float32)
    cos2 = float(np.cos(np.radians(edge_angle_deg)) ** 2)

    # edge keep flags on the grid (NaN ends are never kept)
    h = _keep_edges(P[:, :-1], P[:, 1:], center, cos2)  # (H, W-1): (r,c)-(r,c+1)
    v = _keep_edges(P[:-1, :], P[1:, :], center, cos2)  # (H-1, W): (r,c)-(r+1,c)
    dad = _keep_edges(P[:-1, :-1], P[1:, 1:], center, cos2)  # (H-1, W-1): a-d
    dbc = _keep_edges(P[:-1, 1:], P[1:, :-1], center, cos2)  # (H-1, W-1): b-c

    ab, cd = h[:-1, :], h[1:, :]
    ac, bd = v[:, :-1], v[:, 1:]
    # split A (diagonal a-d): T1 = (a, c, d), T2 = (a, d, b)
    t1 = ac & cd & dad
    t2 = dad & ab & bd
    # split B (diagonal b-c): T3 = (a, c, b), T4 = (b, c, d)
    t3 = ac & dbc & ab
    t4 = dbc & bd & cd
    nA = t1.astype(np.int8) + t2
    nB = t3.astype(np.int8) + t4
    with np.errstate(invalid="ignore"):
        lad = np.sum((P[1:, 1:] - P[:-1, :-1]) ** 2, axis=2)
        lbc = np.sum((P[1:, :-1] - P[:-1, 1:]) ** 2, axis=2)
    lad = np.where(np.isnan(lad), np.inf, lad)
    lbc = np.where(np.isnan(lbc), np.inf, lbc)
    useA = (nA > nB) | ((nA == nB) & (lad <= lbc))
    t1 &= useA
    t2 &= useA
    t3 &= ~useA
    t4 &= ~useA

    # flat vertex indices of the quad corners, (H-1, W-1)
    a = (np.arange(H - 1)[:, None] * W + np.arange(W - 1)[None, :]).astype(np.int32)
    b, c, d = a + 1, a + W, a + W + 1
    tris = np.concatenate([
        np.stack([a[t1], c[t1], d[t1]], axis=1),
        np.stack([a[t2], d[t2], b[t2]], axis=1),
        np.stack([a[t3], c[t3], b[t3]], axis=1),
        np.stack([b[t4], c[t4], d[t4]], axis=1),
    ])
    if len(tris) == 0:
        return TriMesh(*_empty_arrays(), in_roi=valid)
    # drop unreferenced vertices
    used = np.zeros(H * W, dtype=bool)
    used[tris.ravel()] = True
    pixel = np.flatnonzero(used).astype(np.int32)
    remap = np.full(H * W, -1, dtype=np.int32)
    remap[pixel] = np.arange(len(pixel), dtype=np.int32)
    verts = np.ascontiguousarray(P.reshape(-1, 3)[pixel])
    return TriMesh(verts, remap[tris], pixel, valid)


def _empty_arrays() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    return np.zeros((0, 3), np.float32), np.zeros((0, 3), np.int32), np.zeros(0, np.int32)


def boundary_edges(triangles: np.ndarray, return_opposite: bool = False):
    """Edges that belong to exactly one triangle, (E, 2) int32 (vertex indices, in the
    direction they run in their triangle). With ``return_opposite``, also the third vertex of
    that triangle for each edge, (E,) int32."""
    tri = np.asarray(triangles, dtype=np.int64)
    if len(tri) == 0:
        z = np.zeros((0, 2), np.int32)
        return (z, np.zeros(0, np.int32)) if return_opposite else z
    e = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
    lo = np.minimum(e[:, 0], e[:, 1])
    hi = np.maximum(e[:, 0], e[:, 1])
    key = lo * (int(tri.max()) + 1) + hi
    order = np.argsort(key, kind="stable")
    ks = key[order]
    n = len(ks)
    single = np.ones(n, dtype=bool)
    same = ks[1:] == ks[:-1]
    single[1:] &= ~same
    single[:-1] &= ~same
    sel = order[single]
    edges = e[sel].astype(np.int32)
    if not return_opposite:
        return edges
    F = len(tri)
    opposite = tri[sel % F, (sel // F + 2) % 3].astype(np.int32)  # edge k of a triangle: vertices k, k+1
    return edges, opposite


#: Depth difference across a cut edge below which it is taken for noise, not for the edge of a
#: surface: no skirt there (ToF noise is a few millimetres; leaf layers are further apart).
SKIRT_MIN_JUMP_M = 0.01


def extend_boundary(mesh: TriMesh, depth_cam: Camera, width_px: float = 0.5,
                    depth_m: np.ndarray | None = None, min_jump_m: float = SKIRT_MIN_JUMP_M,
                    flying: np.ndarray | None = None, depth_raw: np.ndarray | None = None) -> TriMesh:
    """Add a skirt of ``width_px`` depth pixels around the mesh's boundary, in the plane of each
    boundary vertex's depth.

    The mesh through the depth-pixel centres stops half a pixel short of the surface each pixel
    actually measured: a depth pixel at a silhouette covers the surface up to its own edge. The
    skirt restores that half pixel, so that sources grazing a leaf edge are judged against where
    the edge most likely is (halfway to the next pixel) rather than systematically inside it;
    the uncertainty mesh then hangs from the skirt's outer edge. Each boundary vertex is moved
    outwards in the depth image (along the mean outward normal of its boundary edges, mitred so
    that the edges move by ``width_px``; not at pinch vertices where boundaries meet) and
    back-projected at its own depth. Skirt vertices have ``pixel`` -1.

    With ``depth_m`` (H, W metres), only boundaries that are real surface edges get a skirt:
    the neighbouring depth pixel in the outward direction has no measurement inside the ROI, or
    differs in depth by more than ``min_jump_m``. Holes that depth noise cuts into a smooth
    surface (small jumps) get none: a skirt there would stand out of the surface as a false
    occluder.

    ``flying`` (H, W) bool: depth pixels removed as flying (their raw depths in ``depth_raw``).
    A flying pixel straddles the edge, so the edge lies *inside* it: a boundary vertex whose
    outward neighbour is flying gets, on top of ``width_px``, the share of that pixel's
    footprint its own surface covers, estimated from the mixed depth as
    ``1 - |z_fly - z_own| / |z_beyond - z_own|`` (``z_beyond``: the next pixel outwards; 0.5
    when it has no usable depth). Without it, removing flying pixels would shrink every
    silhouette by about half a pixel.
    """
    if mesh.n_triangles == 0 or width_px <= 0 or mesh.pixel is None:
        return mesh
    edges, opp = boundary_edges(mesh.triangles, return_opposite=True)
    if len(edges) == 0:
        return mesh
    W = depth_cam.width
    pix = np.stack([mesh.pixel % W, mesh.pixel // W], axis=1).astype(np.float64)  # (u, v) per vertex
    pi, pj, pk = pix[edges[:, 0]], pix[edges[:, 1]], pix[opp]
    d = pj - pi
    n = np.stack([-d[:, 1], d[:, 0]], axis=1)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    n[np.einsum("ij,ij->i", n, pk - pi) > 0] *= -1  # point away from the edge's triangle
    ids, inv = np.unique(edges, return_inverse=True)
    inv = inv.reshape(-1, 2)
    acc = np.zeros((len(ids), 2))
    np.add.at(acc, inv[:, 0], n)
    np.add.at(acc, inv[:, 1], n)
    cnt = np.bincount(inv.ravel(), minlength=len(ids))
    norm = np.linalg.norm(acc, axis=1)
    ok = (cnt == 2) & (norm > 0.5)  # a simple boundary vertex with a defined outward direction
    dirn = np.zeros_like(acc)
    dirn[ok] = acc[ok] / norm[ok, None]
    # mitre: both edges move by width_px; cos of the half angle = |sum| / 2
    if depth_m is not None:
        H = depth_cam.height
        step = np.rint(dirn).astype(np.int64)
        nu = (mesh.pixel[ids] % W) + step[:, 0]
        nv = (mesh.pixel[ids] // W) + step[:, 1]
        inside = (nu >= 0) & (nu < W) & (nv >= 0) & (nv < H) & np.any(step != 0, axis=1)
        nflat = np.where(inside, nv * W + nu, 0)
        d = np.asarray(depth_m, dtype=np.float64).reshape(-1)
        measured = inside & (mesh.in_roi.reshape(-1)[nflat] if mesh.in_roi is not None else np.isfinite(d[nflat]))
        with np.errstate(invalid="ignore"):
            small_jump = measured & (np.abs(d[nflat] - d[mesh.pixel[ids]]) <= min_jump_m)
        ok &= ~small_jump
    width = np.full(len(ids), float(width_px))
    if depth_m is not None and flying is not None and depth_raw is not None and flying.any():
        fly = flying.reshape(-1)
        toward = inside & fly[nflat]
        if toward.any():
            raw = np.asarray(depth_raw, dtype=np.float64).reshape(-1)
            own = d[mesh.pixel[ids]]
            nu2, nv2 = nu + step[:, 0], nv + step[:, 1]
            in2 = toward & (nu2 >= 0) & (nu2 < W) & (nv2 >= 0) & (nv2 < H)
            n2 = np.where(in2, nv2 * W + nu2, 0)
            other = np.where(in2 & ~fly[n2], raw[n2], np.nan)
            with np.errstate(invalid="ignore", divide="ignore"):
                share = 1.0 - np.abs(raw[nflat] - own) / np.abs(other - own)
            share = np.where(np.isfinite(share), np.clip(share, 0.0, 1.0), 0.5)
            width += np.where(toward, share, 0.0)
    dist = np.where(ok, width / np.maximum(norm / 2, 0.5), 0.0)
    new_uv = pix[ids] + dirn * dist[:, None]
    X_top = mesh.vertices[ids].astype(np.float64)
    z = depth_cam.to_cam(X_top)[:, 2]
    xy = depth_cam.undistort_normalized(new_uv)
    X_new = depth_cam.to_rig(np.concatenate([xy, np.ones((len(xy), 1))], axis=1) * z[:, None])
    V = mesh.n_vertices
    i, j = inv[:, 0], inv[:, 1]
    ii, jj = edges[:, 0], edges[:, 1]
    skirt = np.concatenate([np.stack([ii, jj, j + V], axis=1), np.stack([ii, j + V, i + V], axis=1)])
    keep = np.concatenate([ok[j] | ok[i], ok[j] | ok[i]])  # both skirt vertices unmoved: degenerate
    verts = np.concatenate([mesh.vertices, X_new.astype(np.float32)])
    tris = np.concatenate([mesh.triangles, skirt[keep].astype(np.int32)])
    pixel = np.concatenate([mesh.pixel, np.full(len(ids), -1, np.int32)])
    # drop skirt vertices no triangle uses
    used = np.zeros(len(verts), dtype=bool)
    used[tris.ravel()] = True
    remap = np.cumsum(used, dtype=np.int64).astype(np.int32) - 1
    return TriMesh(verts[used], remap[tris], pixel[used], mesh.in_roi)


def uncertainty_mesh(mesh: TriMesh, camera_center: np.ndarray, ground_z: float) -> TriMesh:
    """Curtains hanging from the object mesh's boundary edges along the depth camera's rays down
    to the plane z = ``ground_z`` (rig frame), two triangles per boundary edge.

    ``camera_center`` (3,) the depth camera centre in the rig frame. Vertices at or below the
    ground stay where they are (their curtain is degenerate and never hit).
    """
    edges = boundary_edges(mesh.triangles)
    if len(edges) == 0:
        return TriMesh.empty()
    ids, inv = np.unique(edges, return_inverse=True)
    inv = inv.reshape(-1, 2).astype(np.int32)
    top = mesh.vertices[ids].astype(np.float64)
    C = np.asarray(camera_center, dtype=np.float64)
    dz = top[:, 2] - C[2]
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(dz > 0, (ground_z - C[2]) / dz, 1.0)
    s = np.maximum(s, 1.0)  # never move a vertex towards the camera
    floor = C + (top - C) * s[:, None]
    n = len(ids)
    verts = np.concatenate([top, floor]).astype(np.float32)
    i, j = inv[:, 0], inv[:, 1]
    tris = np.concatenate([np.stack([i, j, j + n], axis=1), np.stack([i, j + n, i + n], axis=1)]).astype(np.int32)
    pixel = None
    if mesh.pixel is not None:
        pixel = np.concatenate([mesh.pixel[ids], np.full(n, -1, np.int32)]).astype(np.int32)
    return TriMesh(verts, tris, pixel)
