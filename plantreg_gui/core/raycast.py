"""Ray casting into triangle meshes (Open3D ``RaycastingScene`` / Embree) and the fast camera
geometry the registration needs for whole pixel grids.

Ray conventions: a ray is ``origin + t * direction``; Open3D measures ``t`` in units of the
direction vector's length (directions need not be unit length). All rays are float32, as
Embree wants them; rays are cast in chunks so that a 4K pixel grid does not need gigabytes
of temporaries.

Why not :meth:`Camera.project` / :meth:`Camera.rays_cam` for whole images: OpenCV's
``projectPoints`` and ``undistortPoints`` cost ~0.5-1 microsecond per point, i.e. seconds for a
4K image. :func:`project_points` evaluates the same OpenCV distortion model vectorised in numpy
(identical results to ~1e-9 px), and :func:`pixel_rays_cam` undistorts a full pixel grid by
exact OpenCV undistortion of a coarse grid and Newton steps on the forward model in between (a
per-pixel check of the forward model redoes the few pixels whose residual exceeds 1e-4 px exactly).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from .camera import Camera

#: Rays per Open3D call: bounds the temporaries (cast_rays returns ~40 bytes per ray).
RAY_CHUNK = 1 << 20

#: Open3D's ray casting holds the GIL for a whole call (1M rays ~ 0.5-1.3 s), which freezes the GUI
#: thread while a worker registers; calls are split so that none holds it for more than ~40 ms.
GIL_CHUNK = 1 << 15

#: Largest acceptable error of the interpolated undistortion, pixels.
_UNDISTORT_TOL_PX = 1e-4

#: Newton steps of the grid undistortion stop when every pixel is this close, pixels.
_NEWTON_TOL_PX = 1e-6

#: Elements per vectorised step of the camera polynomials (keeps temporaries in cache).
_CHUNK = 1 << 16


# ---------------------------------------------------------------------------- camera geometry
def _dist14(cam: Camera) -> np.ndarray:
    d = np.zeros(14)
    d[: min(14, cam.dist.size)] = cam.dist[:14]
    return d


def _has_tilt(cam: Camera) -> bool:
    d = _dist14(cam)
    return bool(d[12] != 0 or d[13] != 0)


def distort_normalized(cam: Camera, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Ideal normalised coordinates (x/z, y/z), (N,) each -> distorted pixel coordinates (u, v),
    float64. Evaluated in cache-sized chunks (the polynomial is memory-bound on big arrays)."""
    n = len(x)
    if n <= _CHUNK:
        return _distort(cam, x, y)
    u = np.empty(n)
    v = np.empty(n)
    for a in range(0, n, _CHUNK):
        u[a : a + _CHUNK], v[a : a + _CHUNK] = _distort(cam, x[a : a + _CHUNK], y[a : a + _CHUNK])
    return u, v


def _distort(cam: Camera, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """OpenCV's model (radial k1..k6 rational, tangential p1 p2, thin prism s1..s4; like
    ``cv2.projectPoints`` the skew K[0, 1] is ignored). Sensor tilt (tauX, tauY) is not
    handled here: callers fall back to OpenCV for tilted models (see :func:`project_points`).
    """
    k1, k2, p1, p2, k3, k4, k5, k6, s1, s2, s3, s4 = _dist14(cam)[:12]
    K = cam.K
    x2, y2, xy = x * x, y * y, x * y
    r2 = x2 + y2
    radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
    if k4 or k5 or k6:
        radial = radial / (1 + r2 * (k4 + r2 * (k5 + r2 * k6)))
    xd = x * radial + 2 * p1 * xy + p2 * (r2 + 2 * x2)
    yd = y * radial + p1 * (r2 + 2 * y2) + 2 * p2 * xy
    if s1 or s2 or s3 or s4:  # thin prism: rare; its array passes are skipped on hot paths (refine's cost)
        r4 = r2 * r2
        xd = xd + s1 * r2 + s2 * r4
        yd = yd + s3 * r2 + s4 * r4
    return K[0, 0] * xd + K[0, 2], K[1, 1] * yd + K[1, 2]


def project_points(cam: Camera, X_rig: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Same as :meth:`Camera.project`, vectorised: rig points (N, 3) -> uv (N, 2) float64, z (N,).

    ``uv`` is NaN for points with ``z <= 0`` (behind the camera) and for non-finite points.
    """
    X_rig = np.asarray(X_rig).reshape(-1, 3)
    if _has_tilt(cam):
        return cam.project(X_rig)
    Xc = X_rig.astype(np.float64) @ cam.R_cam_rig.T + cam.t_cam_rig
    z = Xc[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        iz = 1.0 / z
        u, v = distort_normalized(cam, Xc[:, 0] * iz, Xc[:, 1] * iz)
    uv = np.stack([u, v], axis=1)
    uv[~(z > 0)] = np.nan
    return uv, z


def _grid_rays(cam: Camera, emit) -> None:
    """Undistort every pixel centre of ``cam`` in blocks of rows; ``emit(r0, r1, x, y)`` receives
    the normalised coordinates (float64, ((r1 - r0) * W,) each) of rows r0..r1-1.

    Exact OpenCV undistortion on an 8- or 16-pixel grid; in between, bilinear interpolation of that grid
    as the start and Newton steps on the exact forward model (the grid's local slopes serve as
    the inverse Jacobian), which converge to < 1e-6 px in one or two steps. Pixels still off by
    more than 1e-4 px (a model that folds over) are redone exactly. Plain numpy: no SciPy
    interpolation package to import (~1 s of a command's start-up).
    """
    H, W = cam.height, cam.width
    step = 8 if H * W <= (1 << 21) else 16  # a finer grid saves a Newton step; for 4K the grid itself costs
    if _has_tilt(cam) or H < 4 * step or W < 4 * step:
        xy = cam.undistort_normalized(cam.pixel_grid())
        emit(0, H, xy[:, 0], xy[:, 1])
        return
    ys = np.unique(np.r_[np.arange(0, H, step), H - 1]).astype(np.float64)
    xs = np.unique(np.r_[np.arange(0, W, step), W - 1]).astype(np.float64)
    gu, gv = np.meshgrid(xs, ys)
    g = cam.undistort_normalized(np.stack([gu.ravel(), gv.ravel()], axis=1)).reshape(len(ys), len(xs), 2)
    gx, gy = g[:, :, 0], g[:, :, 1]
    cols = np.arange(W, dtype=np.float64)
    ix = np.minimum(np.searchsorted(xs, cols, side="right") - 1, len(xs) - 2)
    fx = (cols - xs[ix]) / (xs[ix + 1] - xs[ix])
    rows_per_block = max(1, _CHUNK * 4 // W)
    for r0 in range(0, H, rows_per_block):
        r1 = min(H, r0 + rows_per_block)
        rows = np.arange(r0, r1, dtype=np.float64)
        iy = np.minimum(np.searchsorted(ys, rows, side="right") - 1, len(ys) - 2)
        fy = ((rows - ys[iy]) / (ys[iy + 1] - ys[iy]))[:, None]
        dv = (ys[iy + 1] - ys[iy])[:, None]
        du = (xs[ix + 1] - xs[ix])[None, :]

        def along_cols(Gr: np.ndarray) -> np.ndarray:  # (rows, len(xs)) -> (rows * W,)
            return (Gr[:, ix] * (1 - fx) + Gr[:, ix + 1] * fx).ravel()

        # bilinear start value and its Jacobian d(x, y)/d(u, v), both separable in rows, columns
        rx = gx[iy] * (1 - fy) + gx[iy + 1] * fy
        ry = gy[iy] * (1 - fy) + gy[iy + 1] * fy
        x, y = along_cols(rx), along_cols(ry)
        jxu = ((rx[:, ix + 1] - rx[:, ix]) / du).ravel()
        jyu = ((ry[:, ix + 1] - ry[:, ix]) / du).ravel()
        jxv = along_cols((gx[iy + 1] - gx[iy]) / dv)
        jyv = along_cols((gy[iy + 1] - gy[iy]) / dv)
        uu = np.tile(cols, r1 - r0)
        vv = np.repeat(rows, W)
        for it in range(8):
            u, v = distort_normalized(cam, x, y)
            ru, rv = uu - u, vv - v
            if it == 7 or max(np.abs(ru).max(initial=0.0), np.abs(rv).max(initial=0.0)) < _NEWTON_TOL_PX:
                break
            x += jxu * ru + jxv * rv
            y += jyu * ru + jyv * rv
        bad = np.flatnonzero(~((np.abs(ru) < _UNDISTORT_TOL_PX) & (np.abs(rv) < _UNDISTORT_TOL_PX)))
        if bad.size:
            exact = cam.undistort_normalized(np.stack([uu[bad], vv[bad]], axis=1))
            x[bad], y[bad] = exact[:, 0], exact[:, 1]
        emit(r0, r1, x, y)


def pixel_rays_cam(cam: Camera) -> np.ndarray:
    """Viewing directions (z = 1) of every pixel centre in the camera frame, (H*W, 3) float64,
    row-major; equal to ``cam.rays_cam()`` within 1e-4 px but much faster on large images."""
    W = cam.width
    out = np.ones((cam.height * W, 3))

    def emit(r0: int, r1: int, x: np.ndarray, y: np.ndarray) -> None:
        out[r0 * W : r1 * W, 0] = x
        out[r0 * W : r1 * W, 1] = y

    _grid_rays(cam, emit)
    return out


def pixel_rays_rig(cam: Camera, rays_cam: np.ndarray | None = None) -> np.ndarray:
    """Unit ray directions of every pixel in the rig frame, (H*W, 3) float32, row-major.
    Computed block by block (no full-size float64 temporaries for 4K cameras)."""
    W = cam.width
    R = cam.R_cam_rig
    out = np.empty((cam.height * W, 3), dtype=np.float32)

    def emit(r0: int, r1: int, x: np.ndarray, y: np.ndarray) -> None:
        # d_rig = R^T (x, y, 1), normalised
        d = np.empty((len(x), 3))
        for k in range(3):
            d[:, k] = R[0, k] * x + R[1, k] * y + R[2, k]
        d /= np.sqrt(np.einsum("ij,ij->i", d, d))[:, None]
        out[r0 * W : r1 * W] = d

    if rays_cam is not None:
        emit(0, cam.height, rays_cam[:, 0], rays_cam[:, 1])
    else:
        _grid_rays(cam, emit)
    return out


# ---------------------------------------------------------------------------- ray casting
@dataclass
class Hits:
    """First hits of N rays: ``t`` (N,) float32 (inf = none), ``primitive`` (N,) int64 (-1 = none)."""

    t: np.ndarray
    primitive: np.ndarray

    @property
    def hit(self) -> np.ndarray:
        return np.isfinite(self.t)


def rays_may_hit(origin: np.ndarray, R_cam_rig: np.ndarray, dirs: np.ndarray, vertices: np.ndarray,
                 triangles: np.ndarray, margin: float = 1e-4, cells: int = 1024) -> np.ndarray | None:
    """(N,) bool: which rays ``origin`` (3,) + t * ``dirs`` (N, 3) (rig frame, t >= 0) can meet the
    mesh ``vertices`` (V, 3), ``triangles`` (F, 3); False only where a ray certainly misses every
    triangle. None when this bound does not apply (a vertex at or behind the camera plane).

    Why: a 4K target casts 8.3 M rays into meshes that cover a fraction of its view. In the
    camera frame (rotation ``R_cam_rig``, centre ``origin``) every point of a triangle lies in the
    cone of its vertices, so a ray that hits it has its direction's (x/z, y/z) inside the
    bounding box of the vertices' (x/z, y/z). These boxes (``margin`` wider, far beyond float32
    rounding) are marked on a grid of at most ``cells`` x ``cells``; a ray in an unmarked cell
    misses and need not be cast. The rays that are cast give the same hits.
    """
    n = len(dirs)
    tri = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    if len(tri) == 0:
        return np.zeros(n, dtype=bool)
    o = np.asarray(origin, dtype=np.float32).astype(np.float64)  # the origin as cast (float32)
    R = np.asarray(R_cam_rig, dtype=np.float64)
    Vc = (np.asarray(vertices, dtype=np.float64) - o) @ R.T
    if not (Vc[:, 2] > 0).all():
        return None
    x, y = Vc[:, 0] / Vc[:, 2], Vc[:, 1] / Vc[:, 2]
    tx, ty = x[tri], y[tri]
    bx0, bx1 = tx.min(axis=1) - margin, tx.max(axis=1) + margin
    by0, by1 = ty.min(axis=1) - margin, ty.max(axis=1) + margin
    X0, Y0 = bx0.min(), by0.min()
    c = max(bx1.max() - X0, by1.max() - Y0) / cells
    ix0, ix1 = np.floor((bx0 - X0) / c).astype(np.int64), np.floor((bx1 - X0) / c).astype(np.int64)
    iy0, iy1 = np.floor((by0 - Y0) / c).astype(np.int64), np.floor((by1 - Y0) / c).astype(np.int64)
    mark = np.zeros((int(iy1.max()) + 1, int(ix1.max()) + 1), dtype=bool)
    sx, sy = ix1 - ix0, iy1 - iy0
    small = (sx < 4) & (sy < 4)
    for dy in range(4):
        for dx in range(4):
            sel = small & (dx <= sx) & (dy <= sy)
            mark[iy0[sel] + dy, ix0[sel] + dx] = True
    for k in np.flatnonzero(~small):  # long triangles (the uncertainty mesh's curtains): a few thousand
        mark[iy0[k] : iy1[k] + 1, ix0[k] : ix1[k] + 1] = True
    out = np.empty(n, dtype=bool)
    h, w = mark.shape
    for a in range(0, n, RAY_CHUNK):
        d = np.asarray(dirs[a : a + RAY_CHUNK], dtype=np.float64) @ R.T
        z = d[:, 2]
        ok = z > 0
        with np.errstate(divide="ignore", invalid="ignore"):
            iu = np.floor((d[:, 0] / z - X0) / c)
            iv = np.floor((d[:, 1] / z - Y0) / c)
        ok &= (iu >= 0) & (iu < w) & (iv >= 0) & (iv < h)
        sel = np.flatnonzero(ok)
        ok[sel] = mark[iv[sel].astype(np.int64), iu[sel].astype(np.int64)]
        out[a : a + RAY_CHUNK] = ok
    return out


def cast_where(scene: "MeshScene", origin: np.ndarray, dirs: np.ndarray, may: np.ndarray | None,
               check: Callable[[], None] | None = None) -> "Hits":
    """``scene.cast(origin, dirs)`` casting only the rays where ``may`` (N,) bool (None: all);
    the others are misses (see :func:`rays_may_hit`)."""
    if may is None:
        return scene.cast(origin, dirs, check=check)
    idx = np.flatnonzero(may)
    t = np.full(len(dirs), np.inf, dtype=np.float32)
    prim = np.full(len(dirs), -1, dtype=np.int64)
    h = scene.cast(origin, dirs[idx], check=check)
    t[idx], prim[idx] = h.t, h.primitive
    return Hits(t, prim)


class MeshScene:
    """One triangle mesh in an Open3D ``RaycastingScene`` (Embree BVH built on creation).

    ``vertices`` (V, 3) float32, ``triangles`` (F, 3) integer. An empty mesh gives a scene that
    no ray hits. Open3D's triangles are two-sided, which is what a depth-derived surface needs.
    """

    def __init__(self, vertices: np.ndarray, triangles: np.ndarray):
        from .o3d_core import open3d_core

        o3d = open3d_core()  # the ray caster without Open3D's visualisation package (start-up)
        self._o3d = o3d
        self.n_triangles = int(len(triangles))
        self.scene = o3d.t.geometry.RaycastingScene()
        if self.n_triangles:
            self.scene.add_triangles(
                o3d.core.Tensor(np.ascontiguousarray(vertices, dtype=np.float32)),
                o3d.core.Tensor(np.ascontiguousarray(triangles, dtype=np.uint32)),
            )
            # Embree builds its BVH lazily on the first query: do it now, so that the build is
            # timed with the mesh and not with whatever casts first
            self.scene.test_occlusions(o3d.core.Tensor(np.zeros((1, 6), np.float32)))

    def _rays(self, origins: np.ndarray, dirs: np.ndarray) -> "object":
        rays = np.empty((len(dirs), 6), dtype=np.float32)
        rays[:, :3] = origins
        rays[:, 3:] = dirs
        return self._o3d.core.Tensor(rays)

    def cast(self, origins: np.ndarray, dirs: np.ndarray, chunk: int = RAY_CHUNK,
             check: Callable[[], None] | None = None) -> Hits:
        """First hits along rays ``origins`` (3,) or (N, 3) + t * ``dirs`` (N, 3).
        ``check`` is called before every chunk (a cancellation point)."""
        n = len(dirs)
        t = np.full(n, np.inf, dtype=np.float32)
        prim = np.full(n, -1, dtype=np.int64)
        if self.n_triangles == 0 or n == 0:
            return Hits(t, prim)
        origins = np.asarray(origins, dtype=np.float32)
        for a in range(0, n, min(chunk, GIL_CHUNK)):
            if check is not None and a % chunk < GIL_CHUNK:
                check()  # cancellation point per chunk
            b = min(n, a + min(chunk, GIL_CHUNK))
            o = origins if origins.ndim == 1 else origins[a:b]
            r = self.scene.cast_rays(self._rays(o, dirs[a:b]))
            t[a:b] = r["t_hit"].numpy()
            p = r["primitive_ids"].numpy().astype(np.int64)
            p[~np.isfinite(t[a:b])] = -1
            prim[a:b] = p
        return Hits(t, prim)

    def occluded(self, origins: np.ndarray, dirs: np.ndarray, tfar: float = 1.0,
                 chunk: int = RAY_CHUNK, check: Callable[[], None] | None = None) -> np.ndarray:
        """(N,) bool: does the segment ``origin + t * dir``, 0 <= t <= ``tfar``, meet the mesh?

        Embree's any-hit query (cheaper than a closest hit). Scale ``dirs`` per ray to give
        each ray its own end point (Open3D takes one scalar ``tfar``)."""
        n = len(dirs)
        out = np.zeros(n, dtype=bool)
        if self.n_triangles == 0 or n == 0:
            return out
        origins = np.asarray(origins, dtype=np.float32)
        for a in range(0, n, min(chunk, GIL_CHUNK)):
            if check is not None and a % chunk < GIL_CHUNK:
                check()  # cancellation point per chunk
            b = min(n, a + min(chunk, GIL_CHUNK))
            o = origins if origins.ndim == 1 else origins[a:b]
            out[a:b] = self.scene.test_occlusions(self._rays(o, dirs[a:b]), tnear=0.0, tfar=float(tfar)).numpy()
        return out
