"""`plantreg batch` (local pool and a real Dask scheduler + workers), resume, failures, name
clashes; compact outputs (tiled, compressed TIFFs decoded bit-identically, the packed PLY);
start-up without Dash/Plotly/SciPy interpolation/matplotlib."""

from __future__ import annotations

import csv
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import tifffile

from plantreg_gui.cli import main
from plantreg_gui.core.pipeline import batch
from plantreg_gui.core.errors import InputError
from plantreg_gui.core.io.imageio import TIFF_CODECS, dense_tiles, write_tiff_tiled
from plantreg_gui.core.data.recording import Recording
from plantreg_gui.core.registration.register import Registrar
from plantreg_gui.core.camera.rig import Rig

ROOT = Path(__file__).resolve().parents[1]


def _env() -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    return env


@pytest.fixture(scope="module")
def recordings(demo_dir, tmp_path_factory):
    """Three good recordings of the demo rig (the demo recording with the depth map shifted by
    0, 5, 10 mm so that they differ) and one whose depth map is missing."""
    import cv2

    root = tmp_path_factory.mktemp("recs")
    src = demo_dir / "recording"
    good = []
    for k in range(3):
        d = root / f"plant{k}"
        shutil.copytree(src, d)
        m = json.loads((d / "recording.json").read_text())
        depth = cv2.imread(str(d / m["depth"]), cv2.IMREAD_UNCHANGED)
        depth[depth > 0] += np.asarray(5 * k, depth.dtype)
        assert cv2.imwrite(str(d / m["depth"]), depth)
        good.append(d)
    bad = root / "broken"
    bad.mkdir()
    (bad / "recording.json").write_text(json.dumps({"depth": "missing.png", "images": {}}))
    return demo_dir / "rig.json", good, bad


def _rows(out: Path) -> dict[str, dict[str, str]]:
    with open(out / "batch.csv", newline="") as f:
        return {r["name"]: r for r in csv.DictReader(f)}


def _layout(folder: Path) -> list[str]:
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*") if p.is_file())


def _check_outputs_equal_register(rig_path: Path, rec: Path, out: Path, target: str = "ir") -> None:
    """The batch's folder holds exactly what registering the recording in-process gives."""
    rig = Rig.load(rig_path)
    res = Registrar(rig, Recording.load(rec, rig)).register(target)
    for cam, ref in res.registered.items():
        a = tifffile.imread(out / "registered" / f"{cam}.tif")
        assert np.array_equal(a, ref, equal_nan=True), cam
    s = json.loads((out / "summary.json").read_text())
    n = res.area.size
    for cam, counts in res.case_counts().items():
        assert s["cases"][cam]["P1 legitimate"]["pixels"] == counts.get(1, 0)
        assert s["cases"][cam]["P2 occluded"]["percent"] == round(100.0 * counts.get(2, 0) / n, 3)


def test_batch_local_pool_success_failure_resume(recordings, tmp_path, capsys):
    rig, good, bad = recordings
    out = tmp_path / "out"
    code = main(["batch", "--rig", str(rig), "--target", "ir", "--out", str(out), "--workers", "2", "--quiet",
                 *map(str, good), str(bad)])
    stdout = capsys.readouterr().out
    assert code == 1  # one recording failed
    rows = _rows(out)
    assert list(rows) == ["plant0", "plant1", "plant2", "broken"]  # the order given
    assert [rows[f"plant{k}"]["status"] for k in range(3)] == ["done"] * 3
    assert rows["broken"]["status"] == "failed" and "missing.png" in rows["broken"]["error"]
    assert "depth map" in rows["broken"]["error"] and "failed" in stdout
    assert not (out / "broken").exists()
    # register's layout, and the very values register gives
    reg_out = tmp_path / "reg"
    assert main(["register", "--rig", str(rig), "--recording", str(good[1]), "--target", "ir", "--out",
                 str(reg_out), "--quiet"]) == 0
    assert _layout(out / "plant1") == _layout(reg_out)
    _check_outputs_equal_register(rig, good[1], out / "plant1")
    s = json.loads((out / "plant1" / "summary.json").read_text())
    assert float(rows["plant1"]["rgb P1 %"]) == s["cases"]["rgb"]["P1 legitimate"]["percent"]
    assert float(rows["plant1"]["area P4 %"]) == s["areas"]["P4 certain object"]["percent"]
    assert rows["plant1"]["files"].split(";") == s["files"]
    # different depth maps give different results (the jobs did not share meshes)
    a0 = tifffile.imread(out / "plant0/registered/thermal.tif")
    a2 = tifffile.imread(out / "plant2/registered/thermal.tif")
    assert not np.array_equal(a0, a2, equal_nan=True)

    # resume: nothing to do but the failed one
    mtimes = {p: p.stat().st_mtime_ns for p in (out / "plant0").rglob("*")}
    code = main(["batch", "--rig", str(rig), "--target", "ir", "--out", str(out), "--quiet", *map(str, good), str(bad)])
    assert code == 1
    rows = _rows(out)
    assert [rows[f"plant{k}"]["status"] for k in range(3)] == ["skipped"] * 3 and rows["broken"]["status"] == "failed"
    assert mtimes == {p: p.stat().st_mtime_ns for p in (out / "plant0").rglob("*")}

    # a changed input is not silently skipped; --overwrite redoes it
    img = good[0] / "thermal.tif"
    os.utime(img, ns=(img.stat().st_atime_ns, img.stat().st_mtime_ns + 10**9))
    code = main(["batch", "--rig", str(rig), "--target", "ir", "--out", str(out), "--quiet", *map(str, good)])
    rows = _rows(out)
    assert code == 1 and rows["plant0"]["status"] == "failed" and "--overwrite" in rows["plant0"]["error"]
    assert rows["plant1"]["status"] == "skipped"
    code = main(["batch", "--rig", str(rig), "--target", "ir", "--out", str(out), "--quiet", "--overwrite",
                 "--outputs", "registered,summary", str(good[0])])
    assert code == 0 and _rows(out)["plant0"]["status"] == "done"
    assert _layout(out / "plant0") == sorted([f"registered/{c}.tif" for c in ("ir", "rgb", "thermal", "hyperspectral")]
                                             + ["summary.json"])


def test_name_clashes_are_refused_before_any_work(recordings, tmp_path, capsys):
    rig, good, _ = recordings
    other = tmp_path / "elsewhere" / "PLANT0"  # same name but for case
    shutil.copytree(good[0], other)
    out = tmp_path / "out"
    code = main(["batch", "--rig", str(rig), "--target", "ir", "--out", str(out), *map(str, good), str(other)])
    err = capsys.readouterr().err
    assert code == 1 and "clash" in err and "PLANT0" in err and len(err.strip().splitlines()) == 1
    assert not out.exists()
    with pytest.raises(InputError, match="listed twice"):
        batch.plan([good[0], good[0]], out)


def test_manifest_lists_recordings(recordings, tmp_path):
    rig, good, _ = recordings
    man = tmp_path / "list.csv"
    man.write_text("recording,plant id\n# a comment\n" + "".join(f"{p},{i}\n" for i, p in enumerate(good[:2])))
    assert batch.expand_inputs([man]) == good[:2]
    rel = tmp_path / "rel.txt"
    (tmp_path / "sub").mkdir()
    shutil.copytree(good[2], tmp_path / "sub" / "p")
    rel.write_text("sub/p\n\n")
    assert batch.expand_inputs([rel]) == [tmp_path / "sub" / "p"]
    (tmp_path / "empty.txt").write_text("# nothing\n")
    with pytest.raises(InputError, match="empty"):
        batch.expand_inputs([tmp_path / "empty.txt"])


# ---------------------------------------------------------------------- Dask, real processes
def _dask(*args: str, **kw) -> subprocess.Popen:
    exe = Path(sys.executable).with_name("dask")
    cmd = [str(exe), *args] if exe.exists() else [sys.executable, "-m", "distributed.cli.dask_" + args[0], *args[1:]]
    return subprocess.Popen(cmd, env=_env(), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            start_new_session=True, **kw)


def _wait_for(cond, timeout: float, what: str):
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        v = cond()
        if v:
            return v
        time.sleep(0.05)
    raise AssertionError(f"timed out waiting for {what}")


def _stop(p: subprocess.Popen) -> None:
    if p.poll() is None:
        os.killpg(p.pid, signal.SIGTERM)
        try:
            p.wait(10)
        except subprocess.TimeoutExpired:
            os.killpg(p.pid, signal.SIGKILL)
            p.wait(10)


@pytest.fixture
def scheduler(tmp_path):
    sf = tmp_path / "scheduler.json"
    p = _dask("scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard", "--scheduler-file", str(sf))
    try:
        addr = _wait_for(lambda: sf.is_file() and json.loads(sf.read_text() or "{}").get("address"), 60,
                         "the dask scheduler")
        yield addr, sf
    finally:
        _stop(p)


def _worker(sf: Path, name: str) -> subprocess.Popen:
    # --no-nanny: killing the worker process is the worker dying (no nanny restarts it)
    return _dask("worker", "--scheduler-file", str(sf), "--nthreads", "1", "--no-nanny", "--no-dashboard",
                 "--name", name, "--host", "127.0.0.1")


def _batch_process(rig, out, addr, recs) -> subprocess.Popen:
    cmd = [sys.executable, "-m", "plantreg_gui", "batch", "--rig", str(rig), "--target", "ir", "--out", str(out),
           "--scheduler", addr, *map(str, recs)]
    return subprocess.Popen(cmd, env=_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


@pytest.mark.slow
def test_dask_cluster_with_a_failing_recording_and_a_killed_worker(recordings, scheduler, tmp_path):
    rig, good, bad = recordings
    addr, sf = scheduler
    out = tmp_path / "out"
    w1 = _worker(sf, "w1")
    w2 = None
    proc = None
    try:
        proc = _batch_process(rig, out, addr, [*good, bad])
        # the moment w1 is writing an output folder (hidden temporary folder exists) it is killed,
        # and only then a second worker joins: the job must be retried there, not lost
        part = _wait_for(lambda: next(iter(out.glob(".plant*.part")), None) if out.is_dir() else None, 240,
                         "a worker writing an output folder")
        os.killpg(w1.pid, signal.SIGKILL)
        w1.wait(10)
        w2 = _worker(sf, "w2")
        stdout, stderr = proc.communicate(timeout=400)
    finally:
        if proc is not None and proc.poll() is None:
            proc.kill()
        _stop(w1)
        if w2 is not None:
            _stop(w2)
    assert proc.returncode == 1, stderr  # the broken recording failed
    rows = _rows(out)
    assert set(rows) == {"plant0", "plant1", "plant2", "broken"}
    assert rows["broken"]["status"] == "failed" and "missing.png" in rows["broken"]["error"]
    killed = part.name[1:].split(".")[0]
    assert killed in rows
    for k in range(3):
        r = rows[f"plant{k}"]
        assert r["status"] == "done", r  # the killed one too: retried on the second worker
        folder = out / f"plant{k}"
        s = json.loads((folder / "summary.json").read_text())
        assert all((folder / f).is_file() for f in s["files"])
    _check_outputs_equal_register(rig, good[int(killed[-1])], out / killed)
    # nothing half-written under a final name (the killed worker's temporary folder is hidden)
    assert sorted(p.name for p in out.iterdir() if not p.name.startswith(".")) == [
        "batch.csv", "plant0", "plant1", "plant2"]


# ---------------------------------------------------------------------- compact outputs
@pytest.mark.parametrize("codec", list(TIFF_CODECS))
@pytest.mark.parametrize("shape", [(300, 517), (170, 300, 3), (61, 47, 204)])
def test_tiled_compressed_tiff_decodes_bit_identically(tmp_path, codec, shape):
    rng = np.random.default_rng(len(shape) * 7 + shape[0])
    a = rng.normal(size=shape).astype(np.float32) * 1e3
    a[: shape[0] // 2] = np.nan                       # empty tiles
    a[-1, -1] = np.float32(np.inf)                    # specials survive
    a[-2, -2] = np.float32(-0.0)
    p = tmp_path / f"x_{codec}.tif"
    write_tiff_tiled(p, a.shape, np.float32, dense_tiles(a), codec=codec)
    with tifffile.TiffFile(p) as t:
        page = t.pages[0]
        assert page.is_tiled and len(t.pages) == 1
        assert int(page.compression) == TIFF_CODECS[codec][0] and int(page.predictor) == TIFF_CODECS[codec][1]
        b = page.asarray()
        # a region can be fetched without decoding the whole image
        assert len(page.dataoffsets) > 1
    assert b.dtype == np.float32 and b.shape == a.shape
    assert np.array_equal(a.view(np.uint32), b.view(np.uint32))  # bit-identical, NaN payloads and -0 too
    assert p.stat().st_size < a.nbytes * 0.75


def test_registered_tiff_and_ply_hold_the_result_bit_for_bit(demo_dir, tmp_path):
    from plyfile import PlyData

    from plantreg_gui.core.export.export import ply_property_names, write_outputs

    rig = Rig.load(demo_dir / "rig.json")
    rec = Recording.load(demo_dir / "recording", rig)
    res = Registrar(rig, rec).register("thermal")
    out = tmp_path / "out"
    write_outputs(res, rig, rec, out, what=["registered", "ply"])
    assert _layout(out) == sorted([f"registered/{c}.tif" for c in res.registered] + ["pointcloud.ply"])
    v = PlyData.read(str(out / "pointcloud.ply"))["vertex"]
    pts = res.points_rig
    hit = np.isfinite(pts).all(axis=2)
    rows, cols = np.asarray(v["row"]), np.asarray(v["col"])
    assert v.count == hit.sum() and hit[rows, cols].all()
    assert np.array_equal(np.stack([v["x"], v["y"], v["z"]], axis=1), pts[rows, cols])
    for cam, props in ply_property_names(res).items():
        ref = res.registered[cam][rows, cols].reshape(len(rows), -1)
        got = np.stack([np.asarray(v[p]) for p in props], axis=1)
        assert np.array_equal(got, ref, equal_nan=True), cam
    for cam, c in res.cases.items():
        assert np.array_equal(np.asarray(v[f"{cam}_case"]), c[rows, cols])


def test_outputs_option(demo_dir, tmp_path, capsys):
    out = tmp_path / "o"
    assert main(["register", "--rig", str(demo_dir / "rig.json"), "--recording", str(demo_dir / "recording"),
                 "--target", "ir", "--out", str(out), "--quiet", "--outputs", "cases,areas,ply"]) == 0
    assert _layout(out) == sorted(["areas.png", "pointcloud.ply"] + [f"cases/{c}.png" for c in
                                                                     ("rgb", "thermal", "hyperspectral")])
    assert main(["register", "--rig", str(demo_dir / "rig.json"), "--recording", str(demo_dir / "recording"),
                 "--target", "ir", "--out", str(tmp_path / "p"), "--outputs", "cases,pictures"]) == 1
    err = capsys.readouterr().err
    # the choices are listed from core.export.OUTPUT_PARTS, in writing order
    assert "pictures" in err and "registered,previews,cases" in err and not (tmp_path / "p").exists()


def test_colour_tables_match_matplotlib():
    import matplotlib

    from plantreg_gui.core.display.cmap_tables import TABLES
    from plantreg_gui.core.display.display import colormap_lut

    for name in TABLES:
        ref = (matplotlib.colormaps[name](np.linspace(0.0, 1.0, 256))[:, :3] * 255.0 + 0.5).astype(np.uint8)
        assert np.array_equal(colormap_lut(name), ref), name


# ---------------------------------------------------------------------- start-up
def test_register_does_not_import_what_it_does_not_use(demo_dir, tmp_path):
    cmd = [sys.executable, "-X", "importtime", "-m", "plantreg_gui", "register", "--rig", str(demo_dir / "rig.json"),
           "--recording", str(demo_dir / "recording"), "--target", "ir", "--out", str(tmp_path / "o"), "--quiet"]
    p = subprocess.run(cmd, env=_env(), capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stderr[-2000:]
    imported = {line.split("|")[-1].strip() for line in p.stderr.splitlines() if line.startswith("import time:")}
    assert "plantreg_gui.core.registration.register" in imported  # the check sees the run's imports
    # importlib.metadata: ~50 ms (with the email package) only to look up package versions
    for mod in ("dash", "plotly", "flask", "IPython", "matplotlib", "scipy.interpolate", "open3d.visualization",
                "PySide6", "pyvista", "importlib.metadata"):
        assert mod not in imported, mod
    # the ray caster was loaded nevertheless (the registration ran); check the module registry
    probe = ("import sys, runpy; sys.argv = ['plantreg'] + sys.argv[1:]\n"
             "from plantreg_gui.cli import main\nmain(sys.argv[1:])\n"
             "print(sorted(m for m in sys.modules if m.split('.')[0] in ('open3d', 'dash', 'plotly')))")
    p = subprocess.run([sys.executable, "-c", probe, "register", "--rig", str(demo_dir / "rig.json"), "--recording",
                        str(demo_dir / "recording"), "--target", "thermal", "--out", str(tmp_path / "o2"), "--quiet"],
                       env=_env(), capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stderr[-2000:]
    mods = eval(p.stdout.strip().splitlines()[-1])  # noqa: S307 - our own printout
    assert "open3d.pybind" in mods and not [m for m in mods if m.startswith(("dash", "plotly", "open3d.visualization"))]


# ---------------------------------------------------------------------- bounded memory: HitImage
def test_hit_images_equal_the_dense_registration(demo_dir, tmp_path, monkeypatch):
    """Above the size limit the registered images are kept at the hits only; every way of reading
    them (dense, blocks, pixels, the written TIFF and PLY, previews) gives the dense result."""
    from plyfile import PlyData

    from plantreg_gui.core.registration import register as register_mod
    from plantreg_gui.core.display.display import to_rgb8
    from plantreg_gui.core.export.export import write_outputs
    from plantreg_gui.core.registration.hits import HitImage

    rig = Rig.load(demo_dir / "rig.json")
    rec = Recording.load(demo_dir / "recording", rig)
    dense = Registrar(rig, rec).register("rgb")
    monkeypatch.setattr(register_mod, "DENSE_LIMIT_BYTES", 0)
    sparse = Registrar(rig, rec).register("rgb")
    assert all(isinstance(v, HitImage) for v in sparse.registered.values())
    H, W = dense.shape
    hit_mask = np.isfinite(dense.points_rig).all(axis=2)
    rng = np.random.default_rng(3)
    for cam, ref in dense.registered.items():
        hi = sparse.registered[cam]
        assert hi.shape == ref.shape and hi.ndim == ref.ndim and hi.dtype == np.float32
        assert np.array_equal(np.asarray(hi), ref, equal_nan=True), cam
        for r0, c0 in rng.integers(0, [H - 40, W - 40], size=(5, 2)):
            blk = hi.block(r0, r0 + 37, c0, c0 + 40)
            want = ref[r0:r0 + 37, c0:c0 + 40]
            assert (blk is None and np.isnan(want).all()) or np.array_equal(blk, want, equal_nan=True)
        obj = np.argwhere(np.isfinite(ref if ref.ndim == 2 else ref[..., 0]))
        for r, c in [*obj[:: max(1, len(obj) // 7)], (0, 0), (H - 1, W - 1)]:
            assert np.array_equal(hi[int(r), int(c)], ref[int(r), int(c)], equal_nan=True)
        assert np.array_equal(np.isfinite(hi), np.isfinite(ref))  # ufuncs see the dense image
        # display: the same picture (statistics come from a strided subsample of the pixels, which
        # may pick other pixels from the hits alone: allow a level or two on a few pixels)
        mod = rig.camera(cam).modality
        a, b = to_rgb8(hi, modality=mod).astype(int), to_rgb8(ref, modality=mod).astype(int)
        assert np.array_equal(a[~hit_mask], b[~hit_mask]), cam
        assert np.mean(np.abs(a - b).max(axis=2)[hit_mask] <= 2) > 0.99, cam
    out_d, out_s = tmp_path / "d", tmp_path / "s"
    write_outputs(dense, rig, rec, out_d, what=["registered", "ply", "summary"])
    write_outputs(sparse, rig, rec, out_s, what=["registered", "ply", "summary"])
    for cam in dense.registered:
        a = tifffile.imread(out_s / "registered" / f"{cam}.tif")
        assert np.array_equal(a, dense.registered[cam], equal_nan=True)
    vd = PlyData.read(str(out_d / "pointcloud.ply"))["vertex"].data
    vs = PlyData.read(str(out_s / "pointcloud.ply"))["vertex"].data
    assert vd.dtype == vs.dtype and vd.tobytes() == vs.tobytes()
    sd, ss = (json.loads((o / "summary.json").read_text()) for o in (out_d, out_s))
    assert sd["cameras"] == ss["cameras"] and sd["cases"] == ss["cases"]


@pytest.mark.slow
def test_local_worker_killed_mid_write_is_retried(recordings, tmp_path):
    import psutil

    rig, good, _ = recordings
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "plantreg_gui", "batch", "--rig", str(rig), "--target", "ir", "--out", str(out),
           "--workers", "1", *map(str, good[:2])]
    proc = subprocess.Popen(cmd, env=_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        part = _wait_for(lambda: next(iter(out.glob(".plant*.part")), None) if out.is_dir() else None, 240,
                         "the worker writing an output folder")
        workers = [c for c in psutil.Process(proc.pid).children(recursive=True)
                   if "spawn_main" in " ".join(c.cmdline()) and "resource_tracker" not in " ".join(c.cmdline())]
        assert len(workers) == 1
        workers[0].kill()
        stdout, stderr = proc.communicate(timeout=400)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, stderr
    rows = _rows(out)
    killed = part.name[1:].split(".")[0]
    assert rows[killed]["status"] == "done" and rows[killed]["attempts"] == "2"
    assert {r["status"] for r in rows.values()} == {"done"}
    for name in rows:
        s = json.loads((out / name / "summary.json").read_text())
        assert all((out / name / f).is_file() for f in s["files"])
    assert sorted(p.name for p in out.iterdir() if not p.name.startswith(".")) == ["batch.csv", "plant0", "plant1"]
