"""The synthetic ground truth, checked against independent geometry (not against itself)."""

from __future__ import annotations

import json

import numpy as np
import open3d as o3d
import pytest

from plantreg_gui.cli import main as cli_main
from plantreg_gui.core.errors import Cancelled, InputError
from plantreg_gui.core.progress import CancelToken, Reporter
from plantreg_gui.core.data.recording import Recording
from plantreg_gui.core.camera.rig import Rig
from plantreg_gui.core.synthetic import (
    MAT_GROUND, MAT_LEAF0, GroundTruth, demo_rig, ground_truth, make_plant_scene, render_depth,
    render_recording, write_demo,
)
from plantreg_gui.core.synthetic.render import SENSOR_NOISE


@pytest.fixture(scope="module")
def rig():
    return demo_rig()


@pytest.fixture(scope="module")
def scene():
    return make_plant_scene(0)


@pytest.fixture(scope="module")
def rec(rig, scene):
    # no supersampling and no sensor noise: quick, and texture differences are the texture's own
    return render_recording(rig, scene, supersample=1, sensor_noise=False)


@pytest.fixture(scope="module")
def gt(rig, scene):
    return ground_truth(rig, scene, "ir")


@pytest.fixture(scope="module")
def materials(rig, scene, gt):
    """True material per pixel of every camera."""
    return {n: gt.material if n == "ir" else ground_truth(rig, scene, n, sources=[]).material for n in rig.names}


def _project_by_hand(cam, X_rig: np.ndarray) -> np.ndarray:
    """Pinhole + OpenCV distortion (k1 k2 p1 p2 k3 [k4 k5 k6]) written out, (N, 2)."""
    Xc = X_rig @ cam.R_cam_rig.T + cam.t_cam_rig
    x, y = Xc[:, 0] / Xc[:, 2], Xc[:, 1] / Xc[:, 2]
    d = np.zeros(8)
    d[: min(8, cam.dist.size)] = cam.dist[:8]
    k1, k2, p1, p2, k3, k4, k5, k6 = d
    r2 = x * x + y * y
    radial = (1 + k1 * r2 + k2 * r2**2 + k3 * r2**3) / (1 + k4 * r2 + k5 * r2**2 + k6 * r2**3)
    xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    K = cam.K
    return np.stack([K[0, 0] * xd + K[0, 1] * yd + K[0, 2], K[1, 1] * yd + K[1, 2]], axis=1)


# ---------------------------------------------------------------------- rig
def test_demo_rig_geometry(rig, tmp_path):
    assert rig.names == ["ir", "rgb", "thermal", "hyperspectral"]
    assert rig.depth_camera == "ir" and rig.depth_scale == 0.001
    assert rig.ground_z == pytest.approx(1.17) and rig.extra["synthetic"]["ground_plane_z"] == pytest.approx(1.20)
    shapes = {c.name: (c.width, c.height) for c in rig.cameras}
    assert shapes == {"ir": (640, 576), "rgb": (1280, 720), "thermal": (640, 480), "hyperspectral": (256, 256)}
    for c in rig.cameras:
        assert np.any(c.dist != 0), c.name
    ir, rgb, th, hs = (rig.camera(n) for n in rig.names)
    assert np.allclose(ir.R_cam_rig, np.eye(3)) and np.allclose(ir.t_cam_rig, 0)
    # colour camera ~3.2 cm from the depth camera, tilted ~6 degrees
    assert np.linalg.norm(rgb.center_rig) == pytest.approx(0.032, abs=0.003)
    tilt = np.degrees(np.arccos(rgb.R_cam_rig[2] @ [0, 0, 1]))
    assert tilt == pytest.approx(6.0, abs=0.5)
    # thermal: 32.7 x ~24 deg field of view, 10-15 cm off, toed in: its axis passes near (0, 0, 0.8)
    assert np.degrees(2 * np.arctan(th.width / 2 / th.K[0, 0])) == pytest.approx(32.7, abs=0.1)
    assert np.degrees(2 * np.arctan(th.height / 2 / th.K[1, 1])) == pytest.approx(24.5, abs=1.0)
    assert 0.10 <= np.linalg.norm(th.center_rig) <= 0.15
    for cam in (th, hs):
        axis = cam.R_cam_rig[2]
        aim = cam.center_rig + axis * (0.8 - cam.center_rig[2]) / axis[2]
        assert np.linalg.norm(aim - [0, 0, 0.8]) < 0.005, cam.name
    assert np.sign(th.center_rig[0]) != np.sign(hs.center_rig[0])
    assert np.degrees(2 * np.arctan(hs.width / 2 / hs.K[0, 0])) == pytest.approx(31.0, abs=0.1)
    assert len(hs.extra["bands"]) == 100 and hs.extra["bands"][0] == 400 and hs.extra["bands"][-1] == 1000
    assert th.extra["units"] == "degC"
    rig.save(tmp_path / "rig.json")
    back = Rig.load(tmp_path / "rig.json")
    assert back.camera("hyperspectral").extra["bands"] == hs.extra["bands"]
    assert np.allclose(back.camera("ir").dist, ir.dist)

    paper = demo_rig("paper")
    ps = {c.name: (c.width, c.height) for c in paper.cameras}
    assert ps["rgb"] == (3840, 2160) and ps["hyperspectral"] == (512, 512)
    assert len(paper.camera("hyperspectral").extra["bands"]) == 204
    # the same lens on a finer sensor: same field of view
    assert paper.camera("rgb").K[0, 0] / 3840 == pytest.approx(rgb.K[0, 0] / 1280)
    with pytest.raises(InputError):
        demo_rig("huge")


# ---------------------------------------------------------------------- scene and depth
def test_scene_is_fine_and_labelled(scene):
    V, T, M = scene.vertices, scene.triangles, scene.material
    assert len(T) < 2_000_000
    leaf = M >= MAT_LEAF0
    e = np.linalg.norm(V[T[leaf][:, [1, 2, 0]]] - V[T[leaf]], axis=2)
    assert e.max() <= 0.002  # leaf triangle edges <= ~2 mm: the tessellation is the surface
    assert 6 <= scene.n_leaves <= 10
    assert set(np.unique(M)) >= {0, 1, 2, *scene.leaf_ids()}


def test_depth_points_lie_on_true_surface(rig, scene, rec):
    cam = rig.depth()
    depth = rec.depth.astype(np.float64) * rig.depth_scale
    valid = depth > 0
    assert valid.mean() > 0.999  # the ground is everywhere
    # back-project through the camera model: ray with z = 1, times the depth
    X = cam.to_rig(cam.rays_cam()[valid.ravel()] * depth[valid][:, None])
    # unsigned distance to the true mesh (Open3D closest-point query, independent of ray casting)
    rc = o3d.t.geometry.RaycastingScene()
    rc.add_triangles(o3d.core.Tensor(scene.vertices.astype(np.float32)), o3d.core.Tensor(scene.triangles.astype(np.uint32)))
    dist = rc.compute_distance(o3d.core.Tensor(X.astype(np.float32))).numpy()
    # quantisation is +-0.5 mm along z; along the ray that is at most 0.5 mm / cos(ray angle)
    assert dist.max() <= 0.5e-3 * 1.35 + 2e-6
    assert np.median(dist) < 0.3e-3
    # ground pixels are at 1200 mm exactly, the top leaves about 0.5 m from the camera
    assert np.count_nonzero(rec.depth == 1200) > 0.5 * rec.depth.size
    assert 480 <= rec.depth[valid].min() <= 600


def test_depth_noise_has_the_requested_sigma(rig, scene, rec):
    noisy = render_depth(rig, scene, (0.001, 0.001), np.random.default_rng(5)).astype(np.float64)
    clean = rec.depth.astype(np.float64)
    ground = clean == 1200
    diff = (noisy - clean)[ground]  # mm; expected sigma 1 + 0.001 * 1200 = 2.2 mm (+ quantisation)
    assert np.std(diff) == pytest.approx(np.sqrt(2.2**2 + 2 / 12), rel=0.05)
    assert abs(np.mean(diff)) < 0.05


# ---------------------------------------------------------------------- ground truth
def test_ground_truth_points_and_uv_are_exact(rig, gt):
    ir = rig.camera("ir")
    hit = np.isfinite(gt.points_rig[..., 0])
    assert hit.all()
    # the true point lies on the target pixel's ray: it projects back onto the pixel centre
    P = gt.points_rig.reshape(-1, 3)
    uv_ir = _project_by_hand(ir, P)
    assert np.abs(uv_ir - ir.pixel_grid()).max() < 1e-4
    for src in gt.sources:
        cam = rig.camera(src)
        uv = gt.uv[src].reshape(-1, 2)
        mine = _project_by_hand(cam, P)
        assert np.nanmax(np.abs(uv - mine)) < 1e-6, src
        inside = (mine[:, 0] >= -0.5) & (mine[:, 0] <= cam.width - 0.5) & (mine[:, 1] >= -0.5) & (mine[:, 1] <= cam.height - 0.5)
        assert np.array_equal(inside, gt.in_image[src].ravel()), src


def test_object_is_the_roi_and_not_the_ground(rig, gt):
    P = gt.points_rig
    inside = np.all((P >= rig.roi_min) & (P <= rig.roi_max), axis=2)
    assert np.array_equal(inside, gt.object)
    assert np.array_equal(gt.object, gt.material > MAT_GROUND)
    assert 0.05 < gt.object.mean() < 0.5


def test_occlusions_exist_and_visibility_agrees_with_the_source_view(rig, scene, gt):
    obj = gt.object
    for src in gt.sources:
        cam = rig.camera(src)
        occl = gt.occluded(src)
        assert occl.sum() > 0.01 * obj.sum(), src
        assert gt.matchable[src].sum() > 0.6 * obj.sum(), src
        assert np.array_equal(gt.matchable[src], obj & gt.in_image[src] & gt.visible[src])
        # independent check through the *source's* pixel ray (undistortion path, not the segment):
        # a visible point is what the source pixel sees, an occluded one is behind what it sees
        rng = np.random.default_rng(0)
        for mask, want_visible in ((gt.matchable[src], True), (occl, False)):
            idx = np.flatnonzero(mask.ravel())
            idx = rng.choice(idx, min(2000, len(idx)), replace=False)
            P = gt.points_rig.reshape(-1, 3)[idx]
            o, d = cam.rays_rig(gt.uv[src].reshape(-1, 2)[idx])
            t, _prim, _b = scene.cast(o, d)
            D = np.linalg.norm(P - o, axis=1)
            if want_visible:
                assert np.mean(np.abs(t - D) < 1e-3) > 0.995, src
            else:
                assert np.all(t < D - 1e-3), src


def test_leaves_overlap_in_the_depth_view(rec, gt):
    z = rec.depth.astype(np.float64) / 1000.0
    m = gt.material
    pairs = set()
    for a, b, za, zb in ((m[:, 1:], m[:, :-1], z[:, 1:], z[:, :-1]), (m[1:], m[:-1], z[1:], z[:-1])):
        step = (a >= MAT_LEAF0) & (b >= MAT_LEAF0) & (a != b) & (np.abs(za - zb) > 0.05)
        pairs |= {tuple(sorted(p)) for p in zip(a[step].tolist(), b[step].tolist())}
    assert len(pairs) >= 3
    leaf_z = z[m >= MAT_LEAF0]
    assert leaf_z.min() < 0.6 and leaf_z.max() > 0.85  # leaves at several heights


@pytest.mark.parametrize("seed", [1, 2])
def test_other_seeds_also_overlap_and_occlude(rig, seed):
    """The plant generator keeps its promises for other seeds too (geometry only, no rendering)."""
    sc = make_plant_scene(seed)
    g = ground_truth(rig, sc, "ir", sources=["thermal"])
    z, m = g.points_rig[..., 2], g.material
    step = (m[:, 1:] >= MAT_LEAF0) & (m[:, :-1] >= MAT_LEAF0) & (m[:, 1:] != m[:, :-1]) & (np.abs(z[:, 1:] - z[:, :-1]) > 0.05)
    assert step.sum() > 20
    assert g.occluded("thermal").sum() > 0.01 * g.object.sum()
    P = g.points_rig
    assert np.array_equal(np.all((P >= rig.roi_min) & (P <= rig.roi_max), axis=2), g.object)


# ---------------------------------------------------------------------- images
def _medians(img: np.ndarray, material: np.ndarray) -> tuple[float, float]:
    return float(np.median(img[material >= MAT_LEAF0], axis=0).mean()), float(np.median(img[material == MAT_GROUND], axis=0).mean())


def test_images_have_the_rig_sizes_and_modality_traits(rig, rec, materials):
    for cam in rig.cameras:
        assert rec.images[cam.name].shape[:2] == cam.shape, cam.name
    ir, rgb, th, hs = (rec.images[n] for n in rig.names)
    assert ir.dtype == np.uint16 and rgb.dtype == np.uint8 and rgb.shape[2] == 3
    assert th.dtype == np.float32 and hs.dtype == np.float32 and hs.shape[2] == 100
    leaf, ground = _medians(ir.astype(float), materials["ir"])
    assert leaf > 2 * ground                          # active infrared: leaves bright
    leaf_t, ground_t = _medians(th, materials["thermal"])
    assert 18 < leaf_t < ground_t - 3 and ground_t < 32  # leaves cooler than the ground
    g = rgb[materials["rgb"] >= MAT_LEAF0].astype(float)
    assert np.median(g[:, 1] - g[:, 0]) > 20 and np.median(g[:, 1] - g[:, 2]) > 20  # green leaves
    bands = np.array(rig.camera("hyperspectral").extra["bands"])
    spec = np.median(hs[materials["hyperspectral"] >= MAT_LEAF0], axis=0)
    nir, red = spec[np.argmin(abs(bands - 800))], spec[np.argmin(abs(bands - 670))]
    assert nir > 4 * red                              # the vegetation red edge


def test_texture_shows_a_one_pixel_shift(rig, rec, materials):
    """On leaves (the hardest, smoothest material) neighbouring pixels differ by well over the
    sensor noise: a one-pixel misregistration is visible in every modality."""
    for name in rig.names:
        img = rec.images[name].astype(np.float64)
        mat = materials[name]
        same_leaf = (mat[:, 1:] >= MAT_LEAF0) & (mat[:, :-1] == mat[:, 1:])
        d = np.abs(img[:, 1:] - img[:, :-1])[same_leaf]
        d = d.mean(axis=1) if d.ndim == 2 else d
        mod = rig.camera(name).modality
        if mod == "infrared":
            sigma = SENSOR_NOISE["infrared_rel"] * np.median(img[mat >= MAT_LEAF0])
        else:
            sigma = SENSOR_NOISE[mod]
        assert np.mean(d) > 2.5 * sigma, name


# ---------------------------------------------------------------------- writing
def test_write_demo_writes_a_loadable_demo(tmp_path, rig, rec, gt):
    out = tmp_path / "demo"
    paths = write_demo(out, calibration=False, supersample=1, clean=True)
    assert paths["rig"] == out / "rig.json"
    r = Rig.load(out / "rig.json")
    loaded = Recording.load(out / "recording", r)
    assert set(loaded.images) == set(r.names)
    for cam in r.cameras:
        assert loaded.images[cam.name].shape[:2] == cam.shape
    assert np.array_equal(loaded.depth, rec.depth)  # noise-free depth, independent of the image seed
    assert loaded.images["thermal"].dtype == np.float32 and loaded.images["hyperspectral"].shape[2] == 100
    hdr = (out / "recording" / "hyperspectral.hdr").read_text()
    assert "wavelength" in hdr
    manifest = json.loads((out / "recording" / "recording.json").read_text())
    assert manifest["depth"] == "depth.png"
    g = GroundTruth.load(out / "ground_truth" / "ir.npz")
    assert g.target == "ir" and set(g.sources) == {"rgb", "thermal", "hyperspectral"}
    assert np.array_equal(g.matchable["thermal"], gt.matchable["thermal"])
    assert np.allclose(g.uv["rgb"], gt.uv["rgb"], equal_nan=True)
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no temp folders left


def test_demo_command_refuses_a_non_empty_folder(tmp_path, capsys):
    (tmp_path / "x.txt").write_text("keep me")
    assert cli_main(["demo", str(tmp_path)]) == 1
    err = capsys.readouterr().err
    assert "not empty" in err and "Traceback" not in err
    assert [p.name for p in tmp_path.iterdir()] == ["x.txt"]


def test_cancelled_demo_leaves_nothing(tmp_path):
    token = CancelToken()
    token.cancel()
    with pytest.raises(Cancelled):
        write_demo(tmp_path / "demo", progress=Reporter(None, token))
    assert list(tmp_path.iterdir()) == []
