"""Issue 10 speed work that must not change a value: cubes kept at the object hits in small
views (previews, TIFFs, PLY and summary equal to the dense registration's, bit for bit), and
the command line's single-threaded BLAS."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
import tifffile

from plantreg_gui.core.registration import register as register_mod
from plantreg_gui.core.display.display import fit_pca, to_rgb8
from plantreg_gui.core.export.export import write_outputs
from plantreg_gui.core.registration.hits import HitImage
from plantreg_gui.core.data.recording import Recording
from plantreg_gui.core.registration.register import Registrar, keep_at_hits
from plantreg_gui.core.camera.rig import Rig

ROOT = Path(__file__).resolve().parents[1]


def test_which_images_are_kept_at_the_hits():
    # the paper rig: 204-band cube in the 640x576 infrared view (300 MB dense) and in the 4K view
    assert keep_at_hits(576, 640, 204) and keep_at_hits(2160, 3840, 204)
    # RGB and single-band images stay dense up to 1 GB (the 4K RGB target itself: 100 MB)
    assert not keep_at_hits(2160, 3840, 3) and not keep_at_hits(576, 640, 1)
    # small cubes stay dense; a cube in a view above 1 MP stays dense below 1 GB (its preview's
    # statistics are subsampled there: the hits-only preview could pick other pixels)
    assert not keep_at_hits(200, 200, 204)
    assert not keep_at_hits(1100, 1100, 204) and keep_at_hits(1200, 1200, 204)


def test_cube_at_hits_writes_the_dense_outputs(demo_dir, tmp_path, monkeypatch):
    """With the cube kept at the hits, every output (TIFF decoded, previews and mosaic PNGs,
    PLY bytes, summary) equals the dense registration's."""
    rig = Rig.load(demo_dir / "rig.json")
    rec = Recording.load(demo_dir / "recording", rig)
    monkeypatch.setattr(register_mod, "CUBE_HITS_BYTES", 1 << 40)  # the dense registration of before
    dense = Registrar(rig, rec).register("ir")
    cube = next(c for c, v in dense.registered.items() if np.ndim(v) == 3 and v.shape[2] > 4)
    assert isinstance(dense.registered[cube], np.ndarray)
    monkeypatch.setattr(register_mod, "CUBE_HITS_BYTES", 64 << 20)  # the default: the 576 x 640 x 100 cube is 147 MB
    sparse = Registrar(rig, rec).register("ir")
    assert isinstance(sparse.registered[cube], HitImage)
    assert all(isinstance(v, np.ndarray) for c, v in sparse.registered.items() if c != cube)
    mod = rig.camera(cube).modality
    assert np.array_equal(to_rgb8(sparse.registered[cube], modality=mod), to_rgb8(dense.registered[cube], modality=mod))
    out_d, out_s = tmp_path / "d", tmp_path / "s"
    write_outputs(dense, rig, rec, out_d)
    write_outputs(sparse, rig, rec, out_s)
    files = sorted(p.relative_to(out_d) for p in out_d.rglob("*") if p.is_file())
    assert files == sorted(p.relative_to(out_s) for p in out_s.rglob("*") if p.is_file())
    for rel in files:
        a, b = out_d / rel, out_s / rel
        if rel.suffix == ".tif":
            assert tifffile.imread(b).tobytes() == tifffile.imread(a).tobytes(), rel
        elif rel.suffix == ".png":
            assert np.array_equal(cv2.imread(str(a), cv2.IMREAD_UNCHANGED), cv2.imread(str(b), cv2.IMREAD_UNCHANGED)), rel
        elif rel.suffix == ".ply":
            assert a.read_bytes() == b.read_bytes()
    sd, ss = (json.loads((o / "summary.json").read_text()) for o in (out_d, out_s))
    assert sd["cameras"] == ss["cameras"] and sd["cases"] == ss["cases"]


@pytest.mark.parametrize("program", ["plantreg_gui.cli", "plantreg_gui.gui.app"])
def test_programs_run_blas_in_one_thread_unless_told(program):
    # numpy reads the setting once, when it is first imported: the program's module must set it first
    probe = f"import sys, {program}, os; print(os.environ['OPENBLAS_NUM_THREADS'], 'numpy' in sys.modules)"
    env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_NUM_THREADS"}
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    run = lambda e: subprocess.run([sys.executable, "-c", probe], env=e, capture_output=True, text=True,  # noqa: E731
                                   check=True).stdout.strip()
    assert run(env) == "1 False"
    assert run({**env, "OPENBLAS_NUM_THREADS": "3"}) == "3 False"  # the user's setting wins


def test_values_at_a_run_of_hits_is_their_values():
    from plantreg_gui.core.registration.hits import values_at

    rng = np.random.default_rng(5)
    H, W, B = 30, 40, 7
    idx = np.sort(rng.choice(H * W, 300, replace=False))
    vals = rng.random((300, B), dtype=np.float32)
    img = HitImage(idx, vals, (H, W, B))
    dense = np.asarray(img).reshape(H * W, B)
    for flat in (idx, idx[17:200], idx[:1], idx[::2], np.array([idx[3], idx[3] + 1]), np.arange(H * W)):
        got = values_at(img, flat)
        assert got.shape == (len(flat), B) and np.array_equal(got, dense[flat], equal_nan=True)
    run = values_at(img, idx[17:200])
    assert not run.flags.writeable  # a view of the image's own values: not to be changed through it


def test_tiled_writer_with_threads_keeps_tile_order(tmp_path):
    """Many small tiles encoded by several threads, in windows: the file decodes to the image."""
    from plantreg_gui.core.io.imageio import dense_tiles, write_tiff_tiled

    rng = np.random.default_rng(9)
    a = rng.random((333, 517, 204), dtype=np.float32)  # 16 x 16 tiles, ragged edges
    a[rng.random(a.shape[:2]) < 0.6] = np.nan
    a[:100, :200] = np.nan  # empty tiles
    for codec in ("deflate-fp", "zstd"):
        p = tmp_path / f"{codec}.tif"
        write_tiff_tiled(p, a.shape, np.float32, dense_tiles(a), codec=codec, workers=3)
        assert tifffile.imread(p).tobytes() == a.tobytes()


def test_rays_cast_only_where_they_can_hit_give_the_same_registration(demo_dir, monkeypatch):
    """Target rays are computed only in grid cells whose rays can reach a mesh, and cast only where
    they can hit (raycast.pixel_rays_toward, cone_marks): every array of the registration equals
    the one computing and casting all rays, for two targets that cast (thermal, rgb)."""
    from plantreg_gui.core.geometry import raycast

    rig = Rig.load(demo_dir / "rig.json")
    rec = Recording.load(demo_dir / "recording", rig)
    kept = []
    real = register_mod.pixel_rays_toward

    def spy(cam, cones, grid=None):
        pix, dirs = real(cam, cones, grid)
        kept.append(len(pix) / (cam.width * cam.height))
        return pix, dirs

    for target in ("thermal", "rgb"):
        kept.clear()
        with monkeypatch.context() as m:
            m.setattr(register_mod, "pixel_rays_toward", spy)
            fast = Registrar(rig, rec).register(target)
        assert len(kept) == 1 and 0 < kept[0] < 0.9, kept  # a real cut (thermal: the plant fills ~3/4 of its view)
        with monkeypatch.context() as m:
            m.setattr(register_mod, "cone_marks", lambda *a, **k: None)  # no bound: every pixel, every ray
            full = Registrar(rig, rec).register(target)
        assert np.array_equal(fast.points_rig, full.points_rig, equal_nan=True)
        assert np.array_equal(fast.area, full.area)
        for cam in full.cases:
            assert np.array_equal(fast.cases[cam], full.cases[cam]), (target, cam)
        for cam in full.registered:
            assert np.array_equal(np.asarray(fast.registered[cam]), np.asarray(full.registered[cam]), equal_nan=True)
    # the bound itself: rays towards a triangle's corners and centre may hit, rays beside it not
    V = np.array([[0.0, 0.0, 1.0], [0.1, 0.0, 1.0], [0.0, 0.1, 1.0]], np.float32)
    d = np.array([[0.03, 0.03, 1.0], [0.1, 0.0, 1.0], [0.2, 0.0, 1.0], [0.0, -0.05, 1.0], [0.03, 0.03, -1.0]])
    d /= np.linalg.norm(d, axis=1)[:, None]
    T = np.array([[0, 1, 2]])
    cone = raycast.cone_marks(np.zeros(3), np.eye(3), V, T)
    assert cone.rays_may_hit(d.astype(np.float32)).tolist() == [True, True, False, False, False]
    assert raycast.cone_marks(np.zeros(3), np.eye(3), V - [0, 0, 2], T) is None  # behind the camera: no bound


def test_hit_image_preview_uses_the_given_pca_basis():
    """The desktop app renders registered cubes with the raw cube's PCA basis (raw and registered
    look alike); a cube kept at the hits must be drawn with that basis too, not one of its own."""
    rng = np.random.default_rng(1)
    H, W, B = 60, 70, 20
    basis = fit_pca(rng.random((50, 50, B), dtype=np.float32))
    idx = np.sort(rng.choice(H * W, 900, replace=False))
    img = HitImage(idx, rng.random((900, B), dtype=np.float32), (H, W, B))
    a = to_rgb8(img, modality="hyperspectral", pca=basis)
    assert np.array_equal(a, to_rgb8(np.asarray(img), modality="hyperspectral", pca=basis))
    assert not np.array_equal(a, to_rgb8(img, modality="hyperspectral"))  # the basis matters here
