"""Ray casting into triangle meshes (Open3D ``RaycastingScene`` / Embree) and the fast camera
geometry the registration needs for whole pixel grids.

Ray conventions: a ray is ``origin + t * direction``; Open3D measures ``t`` in units of the
direction vector's length (directions need not be unit length). All rays are float32, as
Embree wants them; rays are cast in chunks so that a 4K pixel grid does not need gigabytes
of temporaries.

Why not :meth:`Camera.rays_cam` for whole images: OpenCV's
``undistortPoints`` costs ~0.5-1 microsecond per point, i.e. seconds for a
4K image. :meth:`Camera.project` evaluates the OpenCV distortion model vectorised in numpy
(identical results to ~1e-9 px), and :func:`pixel_rays_cam` undistorts a full pixel grid by
exact OpenCV undistortion of a coarse grid and Newton steps on the forward model in between (a
per-pixel check of the forward model redoes the few pixels whose residual exceeds 1e-4 px exactly).
A target view needs rays only where they can reach the meshes: :func:`pixel_rays_toward` skips
whole grid cells whose rays certainly miss (:func:`cone_marks`), with the same rays elsewhere.

Length: the scenes, the whole-grid undistortion and the cone culling are one mechanism (which
rays to cast and how), tested together against OpenCV and exhaustive casting.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from ..camera.camera import _CHUNK, Camera, _has_tilt, distort_normalized  # noqa: F401 (the lens model)

#: Rays per Open3D call: bounds the temporaries (cast_rays returns ~40 bytes per ray).
RAY_CHUNK = 1 << 20

#: Open3D's ray casting holds the GIL for a whole call (a million rays: a visible freeze of the GUI
#: thread while a worker registers); calls are split into pieces short for the GUI thread.
GIL_CHUNK = 1 << 15

#: Occlusion segments against the uncertainty mesh skip their first centimetre (they all start at
#: a camera centre, and nothing of a plant lies that close to a lens): its scene is made with
#: ``MeshScene(..., skip_m=NEAR_CAMERA_M)``. Why: every curtain of the uncertainty mesh lies in a
#: plane through the depth camera's centre, so a segment starting exactly there starts *in* those
#: planes, and Embree's watertight test then reports grazing hits within ~1 mm of the origin: with
#: the ToF clean-up, 0.1-0.7 % of the depth camera's P1 pixels came out P3.2 (all truly visible).
#: The object mesh has no such planes; its tests start at the centre.
NEAR_CAMERA_M = 0.01

#: Largest acceptable error of the interpolated undistortion, pixels.
_UNDISTORT_TOL_PX = 1e-4

#: Newton steps of the grid undistortion stop when every pixel is this close, pixels.
_NEWTON_TOL_PX = 1e-6

# ---------------------------------------------------------------------------- camera geometry
@dataclass
class RayGrid:
    """Exact OpenCV undistortion of a coarse grid of one camera's pixels, from which every
    pixel's viewing direction is refined (:func:`_grid_rays`), and which bounds them by cells.

    ``xs`` (nx,), ``ys`` (ny,): node columns and rows, pixels (every ``step`` pixels and the last);
    ``gx``, ``gy`` (ny, nx): the nodes' normalised coordinates (x/z, y/z). Cell (j, i) holds the
    pixels of rows ``ys[j]`` .. ``ys[j + 1] - 1`` and columns ``xs[i]`` .. ``xs[i + 1] - 1`` (the
    last cell row and column include the last node). ``steps``: Newton steps every pixel takes
    (see :func:`_newton_steps`). ``margin``: how far, in normalised coordinates, a pixel's ray
    may lie outside the box of its cell's four corners (the distortion's curvature between
    nodes), or None when the grid gives no such bound (a model that folds in the image).
    """

    xs: np.ndarray
    ys: np.ndarray
    gx: np.ndarray
    gy: np.ndarray
    steps: int
    margin: float | None

    @property
    def col_edges(self) -> np.ndarray:
        """(nx,) int: cell i holds columns col_edges[i] .. col_edges[i + 1] - 1."""
        return np.r_[self.xs[:-1], self.xs[-1] + 1].astype(np.int64)

    @property
    def row_edges(self) -> np.ndarray:
        """(ny,) int: cell row j holds rows row_edges[j] .. row_edges[j + 1] - 1."""
        return np.r_[self.ys[:-1], self.ys[-1] + 1].astype(np.int64)

    def cell_boxes(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Bounds x0, x1, y0, y1 (ny - 1, nx - 1) each of the normalised coordinates of every
        pixel of each cell: its corners' box, ``margin`` wider (requires a margin)."""
        assert self.margin is not None
        m = self.margin

        def corners(g: np.ndarray, f) -> np.ndarray:
            return f(f(g[:-1, :-1], g[:-1, 1:]), f(g[1:, :-1], g[1:, 1:]))

        return (corners(self.gx, np.minimum) - m, corners(self.gx, np.maximum) + m,
                corners(self.gy, np.minimum) - m, corners(self.gy, np.maximum) + m)


def ray_grid(cam: Camera) -> RayGrid | None:
    """The coarse undistortion grid of ``cam``; None for sensor-tilt models and images too small
    for a grid (their pixels are undistorted exactly, one by one)."""
    H, W = cam.height, cam.width
    step = 8 if H * W <= (1 << 21) else 16  # a finer grid saves a Newton step; for 4K the grid itself costs
    if _has_tilt(cam) or H < 4 * step or W < 4 * step:
        return None
    ys = np.unique(np.r_[np.arange(0, H, step), H - 1]).astype(np.float64)
    xs = np.unique(np.r_[np.arange(0, W, step), W - 1]).astype(np.float64)
    gu, gv = np.meshgrid(xs, ys)
    g = cam.undistort_normalized(np.stack([gu.ravel(), gv.ravel()], axis=1)).reshape(len(ys), len(xs), 2)
    grid = RayGrid(xs, ys, g[:, :, 0].copy(), g[:, :, 1].copy(), 0, None)
    grid.steps, converged = _newton_steps(cam, grid)
    if converged and (np.diff(grid.gx, axis=1) > 0).all() and (np.diff(grid.gy, axis=0) > 0).all():
        # bilinear interpolation's error on a cell is at most (h_u^2 |f_uu| + h_v^2 |f_vv|) / 8;
        # f'' from the nodes' second divided differences, taken 4x for its change between nodes;
        # plus float32 rounding of the rays and the Newton tolerance
        def d2max(a: np.ndarray, axis: int, nodes: np.ndarray) -> float:  # max |d^2 a / d(u or v)^2|
            def along(h: np.ndarray) -> np.ndarray:
                return h[None, :] if axis == 1 else h[:, None]

            h = np.diff(nodes)
            slope = np.diff(a, axis=axis) / along(h)
            return float(np.abs(2 * np.diff(slope, axis=axis) / along(h[:-1] + h[1:])).max())

        hu, hv = np.diff(xs).max(), np.diff(ys).max()
        grid.margin = max(4 * (hu * hu * d2max(g, 1, xs) + hv * hv * d2max(g, 0, ys)) / 8
                          for g in (grid.gx, grid.gy)) + 1e-6
    return grid


def _newton_steps(cam: Camera, grid: RayGrid) -> tuple[int, bool]:
    """Newton steps every pixel of ``grid``'s camera takes, and whether they converge: as many as
    the pixels a quarter and three quarters across each cell -- where the steps from the
    bilinear start converge slowest -- need to come within :data:`_NEWTON_TOL_PX` (at most 7).
    One count for the whole camera, so that a pixel's ray does not depend on which other pixels
    are computed with it."""
    ce, re = grid.col_edges, grid.row_edges
    cols = np.unique(np.r_[ce[:-1] + np.diff(ce) // 4, ce[:-1] + 3 * np.diff(ce) // 4]).astype(np.float64)
    rows = np.unique(np.r_[re[:-1] + np.diff(re) // 4, re[:-1] + 3 * np.diff(re) // 4]).astype(np.float64)
    x, y, jxu, jxv, jyu, jyv, uu, vv = _bilinear_start(grid, rows, cols)
    for it in range(8):
        u, v = distort_normalized(cam, x, y)
        ru, rv = uu - u, vv - v
        if max(np.abs(ru).max(initial=0.0), np.abs(rv).max(initial=0.0)) < _NEWTON_TOL_PX:
            return it, True
        if it < 7:
            x += jxu * ru + jxv * rv
            y += jyu * ru + jyv * rv
    return 7, False


def _grid_rays(cam: Camera, emit, cells: np.ndarray | None = None, grid: RayGrid | None = None) -> None:
    """Undistort pixel centres of ``cam`` in blocks; ``emit(r0, r1, cols, x, y)`` receives the
    normalised coordinates (float64, ((r1 - r0) * len(cols),) each, row-major) of rows
    r0..r1-1 at columns ``cols`` (ascending int, or None for all columns).

    ``cells`` (ny - 1, nx - 1) bool: only the pixels of these cells of ``grid`` (default: all
    pixels; ignored when the camera has no grid). A pixel's result does not depend on which
    others are computed: it is the same with or without ``cells``.

    Exact OpenCV undistortion on an 8- or 16-pixel grid; in between, bilinear interpolation of that grid
    as the start and Newton steps on the exact forward model (the grid's local slopes serve as
    the inverse Jacobian): the camera's step count for every pixel (one or two,
    :func:`_newton_steps`), then per pixel until < 1e-6 px. Pixels still off by more than 1e-4 px
    (a model that folds over) are redone exactly. Plain numpy: no SciPy interpolation package to
    import (a large share of a command's start-up).
    """
    H, W = cam.height, cam.width
    grid = grid if grid is not None else ray_grid(cam)
    if grid is None:
        xy = cam.undistort_normalized(cam.pixel_grid())
        emit(0, H, None, xy[:, 0], xy[:, 1])
        return
    col_edges, row_edges = grid.col_edges, grid.row_edges
    all_cols = np.arange(W, dtype=np.float64)
    rows_per_block = max(1, _CHUNK * 4 // W)
    j = 0
    while j < len(row_edges) - 1:
        # consecutive cell rows with the same columns form one block (all of them without ``cells``)
        sel = None if cells is None else cells[j]
        j1 = j + 1
        while (j1 < len(row_edges) - 1 and row_edges[j1 + 1] - row_edges[j] <= rows_per_block
               and (sel is None or np.array_equal(cells[j1], sel))):
            j1 += 1
        r0, r1 = int(row_edges[j]), int(row_edges[j1])
        j = j1
        if sel is None:
            cols_i = None
            cols = all_cols
        else:
            if not sel.any():
                continue
            cols_i = np.concatenate([np.arange(col_edges[i], col_edges[i + 1]) for i in np.flatnonzero(sel)])
            cols = cols_i.astype(np.float64)
        x, y = _refine(cam, grid, np.arange(r0, r1, dtype=np.float64), cols)
        emit(r0, r1, cols_i, x, y)


def _bilinear_start(grid: RayGrid, rows: np.ndarray, cols: np.ndarray) -> tuple[np.ndarray, ...]:
    """Start of the Newton steps at the pixel centres ``rows`` x ``cols`` (float64 pixel indices):
    x, y (bilinear interpolation of the grid), their Jacobian d(x, y)/d(u, v) as jxu, jxv, jyu,
    jyv (the grid's local slopes), and the pixels' u, v; ((len(rows) * len(cols),) each, row-major)."""
    xs, ys, gx, gy = grid.xs, grid.ys, grid.gx, grid.gy
    ix = np.minimum(np.searchsorted(xs, cols, side="right") - 1, len(xs) - 2)
    fx = (cols - xs[ix]) / (xs[ix + 1] - xs[ix])
    iy = np.minimum(np.searchsorted(ys, rows, side="right") - 1, len(ys) - 2)
    fy = ((rows - ys[iy]) / (ys[iy + 1] - ys[iy]))[:, None]
    dv = (ys[iy + 1] - ys[iy])[:, None]
    du = (xs[ix + 1] - xs[ix])[None, :]

    def along_cols(Gr: np.ndarray) -> np.ndarray:  # (rows, len(xs)) -> (rows * len(cols),)
        return (Gr[:, ix] * (1 - fx) + Gr[:, ix + 1] * fx).ravel()

    # separable in rows, columns
    rx = gx[iy] * (1 - fy) + gx[iy + 1] * fy
    ry = gy[iy] * (1 - fy) + gy[iy + 1] * fy
    x, y = along_cols(rx), along_cols(ry)
    jxu = ((rx[:, ix + 1] - rx[:, ix]) / du).ravel()
    jyu = ((ry[:, ix + 1] - ry[:, ix]) / du).ravel()
    jxv = along_cols((gx[iy + 1] - gx[iy]) / dv)
    jyv = along_cols((gy[iy + 1] - gy[iy]) / dv)
    uu = np.tile(cols, len(rows))
    vv = np.repeat(rows, len(cols))
    return x, y, jxu, jxv, jyu, jyv, uu, vv


def _refine(cam: Camera, grid: RayGrid, rows: np.ndarray, cols: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Normalised coordinates x, y ((len(rows) * len(cols),) float64 each, row-major) of the pixel
    centres at ``rows`` x ``cols`` (float64 pixel indices): bilinear start from the grid, the
    camera's Newton steps, per-pixel steps where still above the tolerance, exact undistortion
    where the model does not converge."""
    x, y, jxu, jxv, jyu, jyv, uu, vv = _bilinear_start(grid, rows, cols)
    for _ in range(grid.steps):
        u, v = distort_normalized(cam, x, y)
        ru, rv = uu - u, vv - v
        x += jxu * ru + jxv * rv
        y += jyu * ru + jyv * rv
    u, v = distort_normalized(cam, x, y)
    ru, rv = uu - u, vv - v
    # pixels the camera's steps left above the tolerance go on alone (at most 7 steps in all)
    act = np.flatnonzero(~((np.abs(ru) < _NEWTON_TOL_PX) & (np.abs(rv) < _NEWTON_TOL_PX)))
    for _ in range(grid.steps, 7):
        if not act.size:
            break
        x[act] += jxu[act] * ru[act] + jxv[act] * rv[act]
        y[act] += jyu[act] * ru[act] + jyv[act] * rv[act]
        u, v = distort_normalized(cam, x[act], y[act])
        ru[act], rv[act] = uu[act] - u, vv[act] - v
        act = act[~((np.abs(ru[act]) < _NEWTON_TOL_PX) & (np.abs(rv[act]) < _NEWTON_TOL_PX))]
    bad = np.flatnonzero(~((np.abs(ru) < _UNDISTORT_TOL_PX) & (np.abs(rv) < _UNDISTORT_TOL_PX)))
    if bad.size:
        exact = cam.undistort_normalized(np.stack([uu[bad], vv[bad]], axis=1))
        x[bad], y[bad] = exact[:, 0], exact[:, 1]
    return x, y


def pixel_rays_cam(cam: Camera) -> np.ndarray:
    """Viewing directions (z = 1) of every pixel centre in the camera frame, (H*W, 3) float64,
    row-major; equal to ``cam.rays_cam()`` within 1e-4 px but much faster on large images."""
    W = cam.width
    out = np.ones((cam.height * W, 3))

    def emit(r0: int, r1: int, cols, x: np.ndarray, y: np.ndarray) -> None:
        out[r0 * W : r1 * W, 0] = x
        out[r0 * W : r1 * W, 1] = y

    _grid_rays(cam, emit)
    return out


def _rig_dirs(R_cam_rig: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Unit rig-frame directions (N, 3) float64 of the camera-frame rays (x, y, 1), (N,) each:
    R^T (x, y, 1), normalised."""
    R = R_cam_rig
    d = np.empty((len(x), 3))
    for k in range(3):
        d[:, k] = R[0, k] * x + R[1, k] * y + R[2, k]
    d /= np.sqrt(np.einsum("ij,ij->i", d, d))[:, None]
    return d


def pixel_rays_rig(cam: Camera) -> np.ndarray:
    """Unit ray directions of every pixel in the rig frame, (H*W, 3) float32, row-major.
    Computed block by block (no full-size float64 temporaries for 4K cameras). The registration
    computes only the rays that can reach its meshes (:func:`pixel_rays_toward`, the same rows)."""
    W = cam.width
    out = np.empty((cam.height * W, 3), dtype=np.float32)

    def emit(r0: int, r1: int, cols, x: np.ndarray, y: np.ndarray) -> None:
        out[r0 * W : r1 * W] = _rig_dirs(cam.R_cam_rig, x, y)

    _grid_rays(cam, emit)
    return out


def pixel_rays_toward(cam: Camera, cones: list["ConeMarks | None"],
                      grid: RayGrid | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The pixels of ``cam`` whose rays can meet one of the meshes of ``cones`` (:func:`cone_marks`
    from the camera's centre in its frame ``cam.R_cam_rig``; None: no bound), and their rays:
    flat pixel indices (M,) ascending, unit rig-frame directions (M, 3) float32, each bit for bit
    the row of :func:`pixel_rays_rig`. Every other pixel's ray misses every mesh (its
    :meth:`ConeMarks.rays_may_hit` is False), as far as the cell bound holds: the margin is
    4 x the grid's largest second difference, a safety factor over what the curvature between
    nodes needs (worst case seen 6 % of the margin over 30+ strongly distorted cameras), on top
    of the cone marks' own 1e-4 margin; models that fold get no bound (every cell computed).

    Why: a 4K target has 8.3 M pixels and the object covers ~15 % of its view; undistorting
    every pixel (Newton steps) and testing every ray cost seconds in a 4K view. The grid's cells are tested
    whole: a cell's pixels lie within its corners' box (``grid.margin`` wider), and a cell whose
    box meets no marked cone cell is skipped. ``grid``: :func:`ray_grid` of ``cam`` (computed if
    not given).
    """
    W = cam.width
    grid = grid if grid is not None else ray_grid(cam)
    cells = None
    if grid is not None and grid.margin is not None:
        boxes = grid.cell_boxes()
        cells = np.zeros(boxes[0].shape, dtype=bool)
        for cone in cones:
            if cone is None:  # no bound: every cell
                cells[:] = True
                break
            cells |= cone.boxes_may_hit(*boxes)
    idx: list[np.ndarray] = []
    dirs: list[np.ndarray] = []

    def emit(r0: int, r1: int, cols, x: np.ndarray, y: np.ndarray) -> None:
        c = np.arange(W) if cols is None else cols
        idx.append((np.arange(r0, r1)[:, None] * W + c[None, :]).ravel())
        dirs.append(_rig_dirs(cam.R_cam_rig, x, y).astype(np.float32))

    _grid_rays(cam, emit, cells, grid)
    if not idx:
        return np.zeros(0, dtype=np.int64), np.zeros((0, 3), dtype=np.float32)
    return np.concatenate(idx), np.concatenate(dirs)


# ---------------------------------------------------------------------------- ray casting
@dataclass
class Hits:
    """First hits of N rays: ``t`` (N,) float32 (inf = none), ``primitive`` (N,) int64 (-1 = none)."""

    t: np.ndarray
    primitive: np.ndarray

    @property
    def hit(self) -> np.ndarray:
        return np.isfinite(self.t)


@dataclass
class ConeMarks:
    """Where rays from one camera centre can meet a mesh, as a grid over the directions' (x/z, y/z)
    in that camera's frame (see :func:`cone_marks`). ``mark`` (h, w) bool; cell (iv, iu) covers
    x/z in ``X0 + iu * c`` .. ``+ c``, y/z in ``Y0 + iv * c`` .. ``+ c``."""

    R_cam_rig: np.ndarray
    X0: float
    Y0: float
    c: float
    mark: np.ndarray

    def rays_may_hit(self, dirs: np.ndarray) -> np.ndarray:
        """(N,) bool for rig-frame directions ``dirs`` (N, 3): False where the ray certainly misses."""
        n = len(dirs)
        R = self.R_cam_rig
        out = np.empty(n, dtype=bool)
        h, w = self.mark.shape
        for a in range(0, n, RAY_CHUNK):
            d = np.asarray(dirs[a : a + RAY_CHUNK], dtype=np.float64) @ R.T
            z = d[:, 2]
            ok = z > 0
            with np.errstate(divide="ignore", invalid="ignore"):
                iu = np.floor((d[:, 0] / z - self.X0) / self.c)
                iv = np.floor((d[:, 1] / z - self.Y0) / self.c)
            ok &= (iu >= 0) & (iu < w) & (iv >= 0) & (iv < h)
            sel = np.flatnonzero(ok)
            ok[sel] = self.mark[iv[sel].astype(np.int64), iu[sel].astype(np.int64)]
            out[a : a + RAY_CHUNK] = ok
        return out

    def boxes_may_hit(self, x0: np.ndarray, x1: np.ndarray, y0: np.ndarray, y1: np.ndarray) -> np.ndarray:
        """bool, shaped like the bounds: whether a ray with (x/z, y/z) in the box ``x0..x1`` x
        ``y0..y1`` (camera frame, z > 0) can meet the mesh -- any marked cell in the box."""
        h, w = self.mark.shape
        # cells the box covers, clipped to the grid; a box beside the grid covers none
        iu0 = np.floor((x0 - self.X0) / self.c)
        iu1 = np.floor((x1 - self.X0) / self.c)
        iv0 = np.floor((y0 - self.Y0) / self.c)
        iv1 = np.floor((y1 - self.Y0) / self.c)
        inside = (iu1 >= 0) & (iu0 < w) & (iv1 >= 0) & (iv0 < h)
        iu0, iu1 = (np.clip(a, 0, w - 1).astype(np.int64) for a in (iu0, iu1))
        iv0, iv1 = (np.clip(a, 0, h - 1).astype(np.int64) for a in (iv0, iv1))
        S = np.zeros((h + 1, w + 1), dtype=np.int64)  # summed-area table of the marks
        S[1:, 1:] = self.mark.cumsum(axis=0).cumsum(axis=1)
        n = S[iv1 + 1, iu1 + 1] - S[iv0, iu1 + 1] - S[iv1 + 1, iu0] + S[iv0, iu0]
        return inside & (n > 0)


def cone_marks(origin: np.ndarray, R_cam_rig: np.ndarray, vertices: np.ndarray, triangles: np.ndarray,
               margin: float = 1e-4, cells: int = 1024) -> ConeMarks | None:
    """The directions from ``origin`` (3,) in which rays can meet the mesh ``vertices`` (V, 3),
    ``triangles`` (F, 3) (rig frame), in the frame of rotation ``R_cam_rig``. None when this bound
    does not apply (a vertex at or behind the camera plane). An empty mesh marks nothing.

    Every point of a triangle lies in the cone of its vertices, so a ray that hits it has its
    direction's (x/z, y/z) inside the bounding box of the vertices' (x/z, y/z). These boxes
    (``margin`` wider, far beyond float32 rounding) are marked on a grid of at most ``cells`` x
    ``cells``.
    """
    tri = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    R = np.asarray(R_cam_rig, dtype=np.float64)
    if len(tri) == 0:
        return ConeMarks(R, 0.0, 0.0, 1.0, np.zeros((1, 1), dtype=bool))
    o = np.asarray(origin, dtype=np.float32).astype(np.float64)  # the origin as cast (float32)
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
    # each box [iy0, iy1] x [ix0, ix1] as +1/-1 at its corners of a difference grid; the 2D
    # prefix sum counts the boxes over each cell
    h, w = int(iy1.max()) + 1, int(ix1.max()) + 1
    corners = np.concatenate([iy0 * (w + 1) + ix0, (iy1 + 1) * (w + 1) + ix1 + 1,
                              iy0 * (w + 1) + ix1 + 1, (iy1 + 1) * (w + 1) + ix0])
    sign = np.repeat(np.array([1, 1, -1, -1], dtype=np.int64), len(tri))
    diff = np.bincount(corners, weights=sign, minlength=(h + 1) * (w + 1)).reshape(h + 1, w + 1)
    mark = diff.cumsum(axis=0).cumsum(axis=1)[:h, :w] > 0.5
    return ConeMarks(R, float(X0), float(Y0), float(c), mark)


def cast_where(scene: "MeshScene", origin: np.ndarray, dirs: np.ndarray, may: np.ndarray | None,
               check: Callable[[], None] | None = None) -> "Hits":
    """``scene.cast(origin, dirs)`` casting only the rays where ``may`` (N,) bool (None: all);
    the others are misses (see :meth:`ConeMarks.rays_may_hit`)."""
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

    def __init__(self, vertices: np.ndarray, triangles: np.ndarray, skip_m: float = 0.0):
        from .o3d_core import open3d_core

        self.skip_m = float(skip_m)  # the default of :meth:`occluded`'s ``skip_m``

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
                 chunk: int = RAY_CHUNK, check: Callable[[], None] | None = None,
                 skip_m: float | None = None) -> np.ndarray:
        """(N,) bool: does the segment ``origin + t * dir``, 0 <= t <= ``tfar``, meet the mesh?

        Embree's any-hit query (cheaper than a closest hit). Scale ``dirs`` per ray to give
        each ray its own end point (Open3D takes one scalar ``tfar``). ``skip_m`` (default: the
        scene's): the first ``skip_m`` metres of every segment are not tested (see
        :data:`NEAR_CAMERA_M`); a segment shorter than that meets nothing."""
        n = len(dirs)
        out = np.zeros(n, dtype=bool)
        if self.n_triangles == 0 or n == 0:
            return out
        origins = np.asarray(origins, dtype=np.float32)
        skip_m = self.skip_m if skip_m is None else skip_m
        if skip_m > 0:
            dirs = np.asarray(dirs, dtype=np.float32)
            norm = np.sqrt(np.einsum("ij,ij->i", dirs, dirs))
            with np.errstate(divide="ignore", invalid="ignore"):
                step = np.where(norm > 0, np.float32(skip_m) / norm, 0).astype(np.float32)  # t of skip_m
            origins = origins + dirs * step[:, None]
            if np.isfinite(tfar):  # the same end point, the start moved out
                keep = 1 - step / np.float32(tfar)
                dirs = dirs * keep[:, None]
                short = keep <= 0
                if short.any():  # nothing left to test: they meet nothing
                    live = np.flatnonzero(~short)
                    out[live] = self.occluded(origins[live], dirs[live], tfar, chunk, check, skip_m=0.0)
                    return out
        for a in range(0, n, min(chunk, GIL_CHUNK)):
            if check is not None and a % chunk < GIL_CHUNK:
                check()  # cancellation point per chunk
            b = min(n, a + min(chunk, GIL_CHUNK))
            o = origins if origins.ndim == 1 else origins[a:b]
            out[a:b] = self.scene.test_occlusions(self._rays(o, dirs[a:b]), tnear=0.0, tfar=float(tfar)).numpy()
        return out


def segment_dirs(origin: np.ndarray, points: np.ndarray, stop_before_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Directions (N, 3) float32 from ``origin`` (3,) towards ``points`` (N, 3), scaled so that
    t = 1 lies ``stop_before_m`` before each point; and a mask (N,) of usable segments."""
    vec = points.astype(np.float32) - origin.astype(np.float32)
    dist = np.sqrt(np.einsum("ij,ij->i", vec, vec))
    with np.errstate(divide="ignore", invalid="ignore"):
        scale = 1.0 - np.float32(stop_before_m) / dist
    usable = scale > 0
    vec *= np.where(usable, scale, 0)[:, None]
    return vec, usable
