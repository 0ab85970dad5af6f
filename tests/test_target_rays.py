"""Target rays only where they can reach a mesh (issue 10, raycast.pixel_rays_toward): the grid
cells whose rays certainly miss both meshes are skipped whole. Checked against the full
computation (every pixel's ray, every ray's cone test) on plant scenes and cameras of seeds the
code was not developed on, and the rays against OpenCV's exact undistortion; and the sampling of
band-sequential cubes in blocks."""

from __future__ import annotations

import numpy as np
import pytest

from plantreg_gui.core.geometry import raycast
from plantreg_gui.core.camera.camera import Camera
from plantreg_gui.core.registration.register import RegistrationParams, build_meshes
from plantreg_gui.core.synthetic.demo import AIM_POINT, demo_rig
from plantreg_gui.core.synthetic.render import render_depth
from plantreg_gui.core.synthetic.scene import make_plant_scene


def _look_at(center: np.ndarray, aim: np.ndarray, roll: float) -> tuple[np.ndarray, np.ndarray]:
    z = (aim - center) / np.linalg.norm(aim - center)
    x = np.cross([0.0, 1.0, 0.0], z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    c, s = np.cos(roll), np.sin(roll)
    R = np.array([c * x + s * y, -s * x + c * y, z])  # rows: camera axes in the rig frame
    return R, -R @ center


def _random_camera(rng: np.random.Generator, w: int, h: int) -> Camera:
    """A camera looking at the plant from beside the depth camera, with a strong random distortion
    (radial, tangential, sometimes rational or thin prism)."""
    f = rng.uniform(0.7, 1.3) * w
    K = [[f, 0, w / 2 + rng.uniform(-20, 20)], [0, f * rng.uniform(0.98, 1.02), h / 2 + rng.uniform(-20, 20)], [0, 0, 1]]
    dist = [rng.uniform(-0.3, 0.3), rng.uniform(-0.1, 0.1), rng.uniform(-1e-3, 1e-3), rng.uniform(-1e-3, 1e-3),
            rng.uniform(-0.02, 0.02)]
    kind = rng.integers(3)
    if kind >= 1:  # rational
        dist += [rng.uniform(-0.3, 0.4), rng.uniform(-0.02, 0.02), rng.uniform(-0.01, 0.01)]
    if kind == 2:  # thin prism
        dist += [rng.uniform(-2e-3, 2e-3) for _ in range(4)]
    center = np.array([rng.uniform(-0.15, 0.15), rng.uniform(-0.15, 0.15), rng.uniform(-0.02, 0.05)])
    R, t = _look_at(center, AIM_POINT + rng.uniform(-0.1, 0.1, 3), rng.uniform(-0.3, 0.3))
    return Camera("c", "rgb", w, h, K, dist, R, t)


@pytest.mark.parametrize("seed", [31, 32, 33])
def test_rays_toward_the_meshes_are_all_that_can_hit(seed):
    """Every pixel left out certainly misses both meshes (the cone test of its full-computation
    ray says so); every ray computed is bit for bit the full computation's."""
    rng = np.random.default_rng(seed)
    rig = demo_rig()
    depth = render_depth(rig, make_plant_scene(seed)).astype(np.float32) * rig.depth_scale
    depth[depth == 0] = np.nan
    meshes = build_meshes(rig, depth, RegistrationParams())
    for w, h in ((1200, 900), (2048, 1152)):  # 8- and 16-pixel grids
        cam = _random_camera(rng, w, h)
        cones = [raycast.cone_marks(cam.center_rig, cam.R_cam_rig, m.vertices, m.triangles)
                 for m in (meshes.object, meshes.uncertainty)]
        assert all(c is not None for c in cones)
        pix, dirs = raycast.pixel_rays_toward(cam, cones)
        full = raycast.pixel_rays_rig(cam)
        assert np.all(np.diff(pix) > 0)
        assert np.array_equal(dirs, full[pix])
        left_out = np.ones(len(full), dtype=bool)
        left_out[pix] = False
        for cone in cones:
            may = cone.rays_may_hit(full)
            assert may.any() and not (may & left_out).any()
        grid = raycast.ray_grid(cam)
        assert grid is not None and grid.margin is not None
        assert 0.02 < len(pix) / len(full) < 0.8, len(pix) / len(full)  # a real cut, and not everything
    # meshes that no ray can reach: no pixel at all
    empty = raycast.cone_marks(cam.center_rig, cam.R_cam_rig, np.zeros((0, 3)), np.zeros((0, 3), int))
    pix, dirs = raycast.pixel_rays_toward(cam, [empty, empty])
    assert pix.shape == (0,) and dirs.shape == (0, 3)


@pytest.mark.parametrize("seed", [41, 42, 43, 44])
def test_pixels_lie_in_their_cells_boxes(seed):
    """The bound the cut rests on: each pixel's undistorted coordinates (exact OpenCV) lie in its
    grid cell's box; the fast rays equal OpenCV's within 1e-4 px."""
    rng = np.random.default_rng(seed)
    cam = _random_camera(rng, 1000, 700)
    grid = raycast.ray_grid(cam)
    assert grid is not None and grid.margin is not None
    x0, x1, y0, y1 = grid.cell_boxes()
    rays = raycast.pixel_rays_cam(cam)
    sub = rng.choice(len(rays), 20000, replace=False)
    exact = cam.rays_cam(cam.pixel_grid()[sub])
    assert np.abs(rays[sub, :2] - exact[:, :2]).max() * cam.K[0, 0] < 1e-4
    v, u = np.divmod(np.arange(len(rays)), cam.width)
    j = np.searchsorted(grid.row_edges, v, side="right") - 1
    i = np.searchsorted(grid.col_edges, u, side="right") - 1
    x, y = rays[:, 0], rays[:, 1]
    assert np.all((x >= x0[j, i]) & (x <= x1[j, i]) & (y >= y0[j, i]) & (y <= y1[j, i]))
    # a bound, not the whole cell: below half the cell's size even at strong distortion
    assert grid.margin < 0.5 * 8 / cam.K[0, 0]


def test_a_subset_of_cells_gives_the_same_rays():
    """A pixel's ray does not depend on which other pixels are computed with it."""
    rng = np.random.default_rng(51)
    cam = _random_camera(rng, 900, 640)
    grid = raycast.ray_grid(cam)
    cells = rng.random((len(grid.ys) - 1, len(grid.xs) - 1)) < 0.3
    got: list[tuple[np.ndarray, np.ndarray]] = []

    def emit(r0, r1, cols, x, y):
        idx = (np.arange(r0, r1)[:, None] * cam.width + cols[None, :]).ravel()
        got.append((idx, np.stack([x, y], axis=1)))

    raycast._grid_rays(cam, emit, cells, grid)
    idx = np.concatenate([g[0] for g in got])
    xy = np.concatenate([g[1] for g in got])
    full = raycast.pixel_rays_cam(cam)
    assert len(idx) == len(np.unique(idx)) and np.array_equal(xy, full[idx, :2])
    v, u = np.divmod(idx, cam.width)
    j = np.searchsorted(grid.row_edges, v, side="right") - 1
    i = np.searchsorted(grid.col_edges, u, side="right") - 1
    assert cells[j, i].all() and len(idx) == sum(
        (grid.row_edges[jj + 1] - grid.row_edges[jj]) * (grid.col_edges[ii + 1] - grid.col_edges[ii])
        for jj, ii in zip(*np.nonzero(cells)))


def test_cone_marks_cover_exactly_the_triangles_boxes():
    """The marks are the union of the triangles' (x/z, y/z) boxes on the grid, small and long ones."""
    rng = np.random.default_rng(61)
    c = np.c_[rng.uniform(-0.3, 0.3, (380, 2)), rng.uniform(0.5, 1.5, 380)]
    V = (c[:, None, :] + rng.uniform(-0.01, 0.01, (380, 3, 3))).reshape(-1, 3)  # small triangles
    T = np.r_[np.arange(3 * 380).reshape(380, 3), rng.integers(0, 3 * 380, (20, 3))]  # and 20 long ones
    cone = raycast.cone_marks(np.zeros(3), np.eye(3), V, T, cells=64)
    x, y = V[:, 0] / V[:, 2], V[:, 1] / V[:, 2]
    want = np.zeros_like(cone.mark)
    for t in T:
        iu = np.floor((np.array([x[t].min() - 1e-4, x[t].max() + 1e-4]) - cone.X0) / cone.c).astype(int)
        iv = np.floor((np.array([y[t].min() - 1e-4, y[t].max() + 1e-4]) - cone.Y0) / cone.c).astype(int)
        want[iv[0] : iv[1] + 1, iu[0] : iu[1] + 1] = True
    assert np.array_equal(cone.mark, want)
    # boxes: any marked cell inside
    b = rng.uniform(-0.4, 0.4, (500, 2))
    s = rng.uniform(0, 0.05, (500, 2))
    got = cone.boxes_may_hit(b[:, 0], b[:, 0] + s[:, 0], b[:, 1], b[:, 1] + s[:, 1])
    for k in range(500):
        iu = np.clip(np.floor((np.array([b[k, 0], b[k, 0] + s[k, 0]]) - cone.X0) / cone.c), -1, want.shape[1]).astype(int)
        iv = np.clip(np.floor((np.array([b[k, 1], b[k, 1] + s[k, 1]]) - cone.Y0) / cone.c), -1, want.shape[0]).astype(int)
        sub = want[max(iv[0], 0) : iv[1] + 1, max(iu[0], 0) : iu[1] + 1]
        assert got[k] == bool(sub.any()), k


@pytest.mark.parametrize("dtype", [np.float32, np.uint16])
def test_sample_bilinear_band_sequential_cube(dtype):
    """A band-sequential cube (ENVI BSQ: an (h, w, C) view of a (C, h, w) array) sampled in
    blocks of samples and bands (C not a multiple of the 4-band group, more samples than a block),
    into given rows of ``out``: equal to SciPy's bilinear interpolation of each band."""
    from scipy.ndimage import map_coordinates

    from plantreg_gui.core.registration.sampling import sample_bilinear

    rng = np.random.default_rng(71)
    C, h, w = 11, 60, 90
    cube = rng.integers(0, 1000, (C, h, w)).astype(dtype).transpose(1, 2, 0)
    assert not cube.flags.c_contiguous
    n = 10_000  # > 2 blocks of 4096 samples
    uv = rng.uniform([-0.5, -0.5], [w - 0.5, h - 0.5], (n, 2))
    uv[:7] = np.nan
    rows = rng.permutation(n + 500)[:n]
    out = np.zeros((n + 500, C), np.float32)
    sample_bilinear(cube, uv, out=out, rows=rows)
    f = cube.astype(np.float64)
    coords = [np.clip(uv[7:, 1], 0, h - 1), np.clip(uv[7:, 0], 0, w - 1)]
    want = np.stack([map_coordinates(f[..., c], coords, order=1) for c in range(C)], axis=1)
    assert np.max(np.abs(out[rows[7:]] - want)) < 1e-3
    rest = np.ones(len(out), bool)
    rest[rows[7:]] = False
    assert np.isnan(out[rest]).all()  # rows without a sample (NaN uv, or not in rows) are NaN


def test_occlusion_segments_skip_the_first_centimetre():
    """``MeshScene.occluded(..., skip_m=)``: a triangle in a plane through the segments' origin (an
    uncertainty curtain seen from the depth camera's centre) is never reported for segments that
    graze it, while a real occluder further out is, and a segment shorter than the skip meets nothing."""
    import numpy as np

    # a curtain in the plane y = 0 from z = 0.4 to 1.0 m, and a leaf across z = 0.5 m
    curtain = np.array([[-0.2, 0.0, 0.4], [0.2, 0.0, 0.4], [0.2, 0.0, 1.0], [-0.2, 0.0, 1.0]], np.float32)
    leaf = np.array([[-0.05, 0.05, 0.5], [0.05, 0.05, 0.5], [0.0, 0.15, 0.5]], np.float32)
    V = np.concatenate([curtain, leaf])
    T = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6]], np.int32)
    scene = raycast.MeshScene(V, T)
    rng = np.random.default_rng(7)
    # segments from the origin to points just off the curtain's plane (angles 1e-7..1e-3 rad)
    ang = 10.0 ** rng.uniform(-7, -3, 2000) * rng.choice([-1, 1], 2000)
    x = rng.uniform(-0.15, 0.15, 2000)
    ends = np.stack([x, 0.9 * np.tan(ang), np.full(2000, 0.9)], axis=1).astype(np.float32)
    hit = scene.occluded(np.zeros(3, np.float32), ends * 0.99, 1.0, skip_m=raycast.NEAR_CAMERA_M)
    assert not hit.any()
    # the leaf: a segment through it is occluded with the skip as without
    through = np.array([[0.0, 0.09, 0.9]], np.float32) * np.float32(0.9 / 0.5)
    assert scene.occluded(np.zeros(3, np.float32), through, 1.0, skip_m=raycast.NEAR_CAMERA_M).all()
    assert scene.occluded(np.zeros(3, np.float32), through / np.linalg.norm(through), np.inf,
                          skip_m=raycast.NEAR_CAMERA_M).all()
    # shorter than the skip: nothing to test
    assert not scene.occluded(np.zeros(3, np.float32), np.array([[0, 0, 0.005]], np.float32), 1.0,
                              skip_m=raycast.NEAR_CAMERA_M).any()
