"""Issue 10, the 4K target's wall time: registered TIFFs encoded while the registration still runs
(export.EarlyTiffs, Registrar.register's ``on_image``), the cube sampled in threads, and a
HitImage's tiles made row by row. Every output must be what the sequential code writes."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest
import tifffile

from plantreg_gui import cli
from plantreg_gui.core.registration import register as register_mod
from plantreg_gui.core.errors import Cancelled
from plantreg_gui.core.export.export import EarlyTiffs, write_outputs
from plantreg_gui.core.registration.hits import HitImage
from plantreg_gui.core.data.recording import Recording
from plantreg_gui.core.registration import sampling
from plantreg_gui.core.registration.register import Registrar
from plantreg_gui.core.registration.sampling import sample_bilinear
from plantreg_gui.core.camera.rig import Rig


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_hit_image_blocks_equal_the_dense_image(seed):
    """Blocks of full rows, partial rows, empty rows, ragged edges, single- and multi-band."""
    rng = np.random.default_rng(seed)
    H, W, B = 53, 71, 5
    occupied = rng.random((H, W)) < rng.uniform(0.2, 0.9)
    occupied[10:30, 20:60] = True  # whole tile rows full
    occupied[40:45] = False
    idx = np.flatnonzero(occupied)
    for shape in ((H, W, B), (H, W)):
        vals = rng.standard_normal((len(idx), shape[2] if len(shape) == 3 else 1)).astype(np.float32)
        img = HitImage(idx, vals, shape)
        dense = np.asarray(img)
        for r0, r1, c0, c1 in [(0, 16, 0, 16), (10, 26, 20, 36), (16, 32, 64, 71), (48, 53, 64, 71),
                               (40, 45, 0, W), (0, H, 0, W), (12, 13, 21, 22)]:
            blk = img.block(r0, r1, c0, c1)
            want = dense[r0:r1, c0:c1]
            if np.isnan(want).all():
                assert blk is None
            else:
                assert blk.shape == want.shape and blk.dtype == np.float32
                assert blk.tobytes() == want.tobytes(), (shape, r0, r1, c0, c1)  # NaN payloads too


@pytest.mark.parametrize("seed", [3, 4])
def test_cube_sampled_in_threads_is_the_sequential_sampling(seed, monkeypatch):
    """A band-sequential cube (ENVI BSQ: a (h, w, C) view of (C, h, w)) sampled in 1 and in 3
    threads, with and without ``out``/``rows``: bit for bit the same."""
    rng = np.random.default_rng(seed)
    C, h, w = 37, 41, 53
    cube = rng.standard_normal((C, h, w)).astype(np.float32).transpose(1, 2, 0)
    n = 30_000  # several chunks of _BAND_ROWS per thread
    uv = np.column_stack([rng.uniform(-1, w, n), rng.uniform(-1, h, n)]).astype(np.float32)
    uv[rng.random(n) < 0.1] = np.nan
    rows = np.sort(rng.choice(n + 500, n, replace=False))
    got = {}
    for threads in (1, 3):
        monkeypatch.setattr(sampling, "SAMPLE_THREADS", threads)
        plain = sample_bilinear(cube, uv)
        out = np.full((n + 500, C), 7.0, np.float32)  # rows not sampled must become NaN
        sample_bilinear(cube, uv, out=out, rows=rows)
        got[threads] = (plain, out)
    for a, b in zip(got[1], got[3]):
        assert a.tobytes() == b.tobytes()
    plain, out = got[1]
    assert np.isnan(out[np.setdiff1d(np.arange(n + 500), rows)]).all()
    # and the samples are the bilinear interpolation (spot check against the formula)
    i = np.flatnonzero(np.isfinite(uv).all(axis=1))[:50]
    u, v = np.clip(uv[i, 0].astype(np.float64), 0, w - 1), np.clip(uv[i, 1].astype(np.float64), 0, h - 1)
    u0, v0 = np.minimum(np.floor(u), w - 2).astype(int), np.minimum(np.floor(v), h - 2).astype(int)
    fu, fv = (u - u0)[:, None], (v - v0)[:, None]
    want = (cube[v0, u0] * (1 - fu) * (1 - fv) + cube[v0, u0 + 1] * fu * (1 - fv)
            + cube[v0 + 1, u0] * (1 - fu) * fv + cube[v0 + 1, u0 + 1] * fu * fv)
    assert np.allclose(plain[i], want, rtol=1e-5, atol=1e-5)


def test_on_image_gets_every_final_image_and_the_order_stays_the_rigs(demo_dir):
    rig = Rig.load(demo_dir / "rig.json")
    rec = Recording.load(demo_dir / "recording", rig)
    seen = {}
    res = Registrar(rig, rec).register("rgb", on_image=lambda cam, img: seen.setdefault(cam, img))
    assert set(seen) == set(res.registered)
    assert all(seen[c] is res.registered[c] for c in seen)  # the very arrays of the result
    sources = [c.name for c in rig.cameras if c.name != "rgb"]
    assert list(res.registered) == ["rgb", *sources]
    assert list(res.cases) == sources and list(res.mixed) == sources
    assert list(res.source_uv) == ["rgb", *sources]
    # the cube is registered first (its TIFF is the longest to write): its stages come first
    cube = max(sources, key=lambda c: rec.images[c].shape[2] if rec.images[c].ndim == 3 else 1)
    stages = [k for k in res.timings if k.startswith("classification")]
    assert stages[0] == f"classification {cube}"


def _same_outputs(a, b):
    files = sorted(p.relative_to(a) for p in a.rglob("*") if p.is_file())
    assert files == sorted(p.relative_to(b) for p in b.rglob("*") if p.is_file())
    for rel in files:
        if rel.suffix == ".tif":
            x, y = tifffile.imread(a / rel), tifffile.imread(b / rel)
            assert x.dtype == y.dtype and x.shape == y.shape and x.tobytes() == y.tobytes(), rel
        elif rel.suffix == ".png":
            x, y = (cv2.imread(str(p / rel), cv2.IMREAD_UNCHANGED) for p in (a, b))
            assert x.shape == y.shape and x.tobytes() == y.tobytes(), rel
        elif rel.suffix == ".ply":
            assert (a / rel).read_bytes() == (b / rel).read_bytes(), rel
    sa, sb = (json.loads((p / "summary.json").read_text()) for p in (a, b))
    for k in ("cameras", "cases", "areas", "points", "stats", "files"):
        assert sa[k] == sb[k], k


@pytest.mark.parametrize("target", ["rgb", "ir"])
def test_register_command_with_early_tiffs_writes_the_sequential_outputs(demo_dir, tmp_path, capsys, target):
    """``plantreg register`` (TIFFs encoded during the registration) against registering first and
    writing after (``write_outputs`` alone); no staging folder is left beside the output."""
    rig = Rig.load(demo_dir / "rig.json")
    rec = Recording.load(demo_dir / "recording", rig)
    late = tmp_path / "late"
    write_outputs(Registrar(rig, rec).register(target), rig, rec, late)
    early = tmp_path / "early"
    code = cli.main(["register", "--rig", str(demo_dir / "rig.json"), "--recording", str(demo_dir / "recording"),
                     "--target", target, "--out", str(early), "--quiet"])
    capsys.readouterr()
    assert code == 0
    _same_outputs(late, early)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["early", "late"]


def test_early_tiffs_stop_and_clean_up_on_an_error(tmp_path):
    """Leaving the context by an error stops the encoding and removes the staging folder; nothing
    appears at the output path."""
    big = np.random.default_rng(0).random((1024, 1024, 16), dtype=np.float32)
    out = tmp_path / "out"
    with pytest.raises(RuntimeError):
        with EarlyTiffs(out) as early:
            early("cube", big)
            early("cube", big)  # once per camera
            raise RuntimeError("registration failed")
    assert list(tmp_path.iterdir()) == []
    # the stop flag ends a running encoding with Cancelled (the file is not written)
    from plantreg_gui.core.export.tiffs import write_registered_tiff as _write_registered_tiff
    import threading

    stop = threading.Event()
    stop.set()
    with pytest.raises(Cancelled):
        _write_registered_tiff(tmp_path / "x.tif", big, "deflate-fp", stop)
    assert list(tmp_path.iterdir()) == []


def test_early_tiff_of_another_image_or_codec_is_not_used(tmp_path):
    img = np.random.default_rng(1).random((40, 50), dtype=np.float32)
    with EarlyTiffs(tmp_path / "out", "deflate-fp") as early:
        early("a", img)
        assert early.has("a", img, "deflate-fp")
        assert not early.has("a", img.copy(), "deflate-fp")  # changed in between: encoded again
        assert not early.has("a", img, "zstd") and not early.has("b", img, "deflate-fp")
        early.take("a", tmp_path / "sub" / "a.tif")
    assert tifffile.imread(tmp_path / "sub" / "a.tif").tobytes() == img.tobytes()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["sub"]


def test_done_reports_only_final_rows(monkeypatch):
    """``sample_bilinear(done=)``: whenever done(k) is called, the first k rows of ``out`` already
    hold their final values (a TIFF writer reads them while the rest is sampled)."""
    rng = np.random.default_rng(6)
    C, h, w = 19, 30, 40
    cube = rng.standard_normal((C, h, w)).astype(np.float32).transpose(1, 2, 0)
    n = 60_000  # several chunks
    uv = np.column_stack([rng.uniform(0, w - 1, n), rng.uniform(0, h - 1, n)]).astype(np.float32)
    uv[rng.random(n) < 0.2] = np.nan
    rows = np.sort(rng.choice(n + 3000, n, replace=False))
    for threads in (1, 2):
        out = np.empty((n + 3000, C), np.float32)
        snapshots = []
        sample_bilinear(cube, uv, out=out, rows=rows, threads=threads,
                        done=lambda k: snapshots.append((k, out[:k].copy())))
        assert snapshots[-1][0] == len(out) and len(snapshots) > 2
        assert [k for k, _ in snapshots] == sorted(k for k, _ in snapshots)
        for k, snap in snapshots:
            assert snap.tobytes() == out[:k].tobytes(), (threads, k)


def test_hit_image_being_filled_waits_for_its_rows():
    """A HitImage handed over while its values are filled: ``block`` returns only final rows, and
    stops with Cancelled when the filler fails."""
    import threading

    from plantreg_gui.core.registration.hits import RowsReady

    H, W, B = 64, 48, 3
    idx = np.arange(0, H * W, 2)
    final = np.random.default_rng(2).random((len(idx), B), dtype=np.float32)
    vals = np.full_like(final, -1.0)
    img = HitImage(idx, vals, (H, W, B))
    img.ready = RowsReady()
    got = {}

    def reader():
        got["block"] = img.block(32, 48, 16, 32)

    t = threading.Thread(target=reader)
    t.start()
    for k in range(0, len(idx), 100):  # filled in steps, as the sampling does
        vals[k : k + 100] = final[k : k + 100]
        img.ready.set(min(len(idx), k + 100))
    t.join(5)
    assert not t.is_alive()
    want = np.asarray(HitImage(idx, final, (H, W, B)))[32:48, 16:32]
    assert got["block"].tobytes() == want.tobytes()
    img2 = HitImage(idx, np.zeros_like(final), (H, W, B))
    img2.ready = RowsReady()
    img2.ready.set(10)
    img2.ready.fail()
    assert img2.block(0, 1, 0, 4) is not None  # rows already final are served
    with pytest.raises(Cancelled):
        img2.block(32, 48, 16, 32)


def test_streamed_cube_in_the_register_command(demo_dir, tmp_path, capsys, monkeypatch):
    """The demo's cube kept at its hits (as the 4K cube is) and streamed into its TIFF while it is
    sampled: the outputs are the sequential ones."""
    monkeypatch.setattr(register_mod, "CUBE_HITS_BYTES", 1 << 20)
    rig = Rig.load(demo_dir / "rig.json")
    rec = Recording.load(demo_dir / "recording", rig)
    streamed = []
    real = register_mod._streamed_hits
    monkeypatch.setattr(register_mod, "_streamed_hits", lambda *a, **k: streamed.append(a[6]) or real(*a, **k))
    late = tmp_path / "late"
    write_outputs(Registrar(rig, rec).register("rgb"), rig, rec, late)
    assert not streamed
    early = tmp_path / "early"
    code = cli.main(["register", "--rig", str(demo_dir / "rig.json"), "--recording", str(demo_dir / "recording"),
                     "--target", "rgb", "--out", str(early), "--quiet"])
    capsys.readouterr()
    assert code == 0 and streamed  # the cube went the streamed way
    _same_outputs(late, early)
