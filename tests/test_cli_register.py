"""`plantreg register`: bad input -> one clear line naming the file, no traceback, no output;
good input -> the documented output folder and a per-source case summary."""

import json
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
import tifffile
from plyfile import PlyData

from plantreg_gui import cli
from plantreg_gui.core.pipeline import pipeline as pipeline_mod
from plantreg_gui.core.registration import register as register_mod
from plantreg_gui.core.camera.camera import Camera
from plantreg_gui.core.data.recording import Recording
from plantreg_gui.core.camera.rig import Rig

W, H = 40, 30


def _K(f, w, h):
    return [[f, 0, (w - 1) / 2], [0, f, (h - 1) / 2], [0, 0, 1]]


def _write_inputs(root: Path, depth_camera="ir"):
    """A tiny valid rig + recording: ir (depth camera), thermal, rgb. Returns (rig_path, rec_dir)."""
    cams = [Camera("ir", "infrared", W, H, _K(40, W, H)),
            Camera("thermal", "thermal", 32, 24, _K(30, 32, 24), t_cam_rig=[0.05, 0, 0]),
            Camera("rgb", "rgb", 80, 60, _K(80, 80, 60), t_cam_rig=[-0.05, 0, 0])]
    rig = Rig(cams, depth_camera=depth_camera, roi_min=[-1, -1, 0.2], roi_max=[1, 1, 1.5])
    rig_path = root / "rig.json"
    rig.save(rig_path)
    if depth_camera is None:  # Rig.save would omit it anyway; make sure the file has none
        d = json.loads(rig_path.read_text())
        assert "depth" not in d
    rec = root / "rec"
    rec.mkdir()
    depth = np.full((H, W), 1000, np.uint16)
    cv2.imwrite(str(rec / "depth.png"), depth)
    np.save(rec / "ir.npy", np.random.default_rng(0).integers(0, 4000, (H, W)).astype(np.uint16))
    tifffile.imwrite(rec / "thermal.tif", np.full((24, 32), 21.5, np.float32))
    cv2.imwrite(str(rec / "rgb.png"), np.zeros((60, 80, 3), np.uint8))
    (rec / "recording.json").write_text(json.dumps(
        {"depth": "depth.png", "images": {"ir": "ir.npy", "thermal": "thermal.tif", "rgb": "rgb.png"}}))
    return rig_path, rec


def _args(rig, rec, out, target="ir", *extra):
    return ["register", "--rig", str(rig), "--recording", str(rec), "--target", target, "--out", str(out),
            "--quiet", *extra]


# each case: (name, how to break the inputs -> (rig, rec, target, out, file the message must name), words)
def _missing_rig(root, rig, rec):
    return root / "nope.json", rec, "ir", root / "nope.json", ["not found"]


def _missing_image(root, rig, rec):
    (rec / "thermal.tif").unlink()
    return rig, rec, "ir", rec / "thermal.tif", ["thermal", "missing"]


def _wrong_size(root, rig, rec):
    tifffile.imwrite(rec / "thermal.tif", np.zeros((20, 30), np.float32))
    return rig, rec, "ir", rec / "thermal.tif", ["30x20", "32x24"]


def _unknown_target(root, rig, rec):
    return rig, rec, "lidar", rig, ["unknown target camera 'lidar'", "thermal"]


def _empty_depth(root, rig, rec):
    cv2.imwrite(str(rec / "depth.png"), np.zeros((H, W), np.uint16))
    return rig, rec, "ir", rec / "depth.png", ["empty"]


def _no_depth_camera(root, rig, rec):
    d = json.loads(rig.read_text())
    del d["depth"]
    rig.write_text(json.dumps(d))
    return rig, rec, "ir", rig, ["no depth camera"]


def _unreadable_image(root, rig, rec):
    (rec / "rgb.png").write_bytes(b"this is not a png at all")
    return rig, rec, "ir", rec / "rgb.png", ["not a PNG file"]


def _depth_wrong_size(root, rig, rec):
    cv2.imwrite(str(rec / "depth.png"), np.full((10, 10), 900, np.uint16))
    return rig, rec, "ir", rec / "depth.png", ["depth map is 10x10"]


def _bad_manifest(root, rig, rec):
    (rec / "recording.json").write_text("{oops")
    return rig, rec, "ir", rec / "recording.json", ["not valid JSON"]


def _binary_manifest(root, rig, rec):
    # starts like UTF-16 (a byte-order mark), which JSON files may be: read so, it is not JSON
    (rec / "recording.json").write_bytes(b"\xff\xfe\x00 not text")
    return rig, rec, "ir", rec / "recording.json", ["not valid JSON"]


def _image_is_a_folder(root, rig, rec):
    (rec / "recording.json").write_text(json.dumps(
        {"depth": "depth.png", "images": {"ir": "ir.npy", "thermal": "sub", "rgb": "rgb.png"}}))
    (rec / "sub").mkdir()
    return rig, rec, "ir", rec / "sub", ["thermal", "folder"]


def _complex_depth(root, rig, rec):
    np.save(rec / "depth.npy", np.full((H, W), 1000, np.complex64))
    (rec / "recording.json").write_text(json.dumps(
        {"depth": "depth.npy", "images": {"ir": "ir.npy", "thermal": "thermal.tif", "rgb": "rgb.png"}}))
    return rig, rec, "ir", rec / "depth.npy", ["real numbers"]


def _rig_scale_not_a_number(root, rig, rec):
    d = json.loads(rig.read_text())
    d["depth"]["scale"] = "1 mm"
    rig.write_text(json.dumps(d))
    return rig, rec, "ir", rig, ["depth.scale must be a number"]


BAD = [_missing_rig, _missing_image, _wrong_size, _unknown_target, _empty_depth, _no_depth_camera,
       _unreadable_image, _depth_wrong_size, _bad_manifest, _binary_manifest, _image_is_a_folder,
       _complex_depth, _rig_scale_not_a_number]


@pytest.mark.parametrize("breaker", BAD, ids=[b.__name__.strip("_") for b in BAD])
def test_bad_input_is_one_clear_line(tmp_path, capsys, breaker):
    rig, rec = _write_inputs(tmp_path)
    rig, rec, target, culprit, words = breaker(tmp_path, rig, rec)
    out = tmp_path / "out"
    code = cli.main(_args(rig, rec, out, target))
    err = capsys.readouterr().err
    assert code != 0
    assert str(culprit) in err, err
    for w in words:
        assert w in err, err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1
    assert not out.exists()
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".out")]


def test_existing_output_is_refused_before_any_work(tmp_path, capsys, monkeypatch):
    rig, rec = _write_inputs(tmp_path)
    out = tmp_path / "out"
    out.mkdir()
    (out / "mine.txt").write_text("keep")

    def never(*a, **k):
        raise AssertionError("registration must not start")

    monkeypatch.setattr(pipeline_mod, "Registrar", never)
    code = cli.main(_args(rig, rec, out))
    err = capsys.readouterr().err
    assert code == 1 and str(out) in err and "not empty" in err and "--overwrite" in err
    assert [p.name for p in out.iterdir()] == ["mine.txt"]


@pytest.mark.parametrize("where", ["recording", "parent"])
def test_overwrite_never_replaces_the_inputs(tmp_path, capsys, monkeypatch, where):
    """--out pointing at the recording folder (or a folder holding it and the rig) with --overwrite
    must be refused before any work: replacing it would delete the user's data."""
    rig, rec = _write_inputs(tmp_path)
    before = sorted(p.name for p in rec.iterdir())

    def never(*a, **k):
        raise AssertionError("registration must not start")

    monkeypatch.setattr(pipeline_mod, "Registrar", never)
    out = rec if where == "recording" else tmp_path
    code = cli.main(_args(rig, rec, out, "ir", "--overwrite"))
    err = capsys.readouterr().err
    assert code == 1 and "would replace an input" in err and "Traceback" not in err
    assert sorted(p.name for p in rec.iterdir()) == before and rig.is_file()


def test_output_under_a_file_is_refused_before_any_work(tmp_path, capsys, monkeypatch):
    rig, rec = _write_inputs(tmp_path)

    def never(*a, **k):
        raise AssertionError("registration must not start")

    monkeypatch.setattr(pipeline_mod, "Registrar", never)
    code = cli.main(_args(rig, rec, rig / "out"))  # the rig file is not a folder
    err = capsys.readouterr().err
    assert code == 1 and str(rig) in err and "Traceback" not in err and len(err.strip().splitlines()) == 1


def test_os_error_while_writing_is_one_line(tmp_path, capsys, monkeypatch):
    """Disk full / no permission while writing: one line naming the file, exit 1, no folder left."""
    import errno

    from plantreg_gui.core.export import tiffs

    rig, rec = _write_inputs(tmp_path)
    monkeypatch.setattr(pipeline_mod, "Registrar", _FakeRegistrar)

    def full(path, *args, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device", str(path))

    monkeypatch.setattr(tiffs, "write_tiff_tiled", full)  # the registered TIFFs
    out = tmp_path / "out"
    code = cli.main(_args(rig, rec, out))
    err = capsys.readouterr().err
    assert code == 1 and "No space left" in err and "Traceback" not in err and len(err.strip().splitlines()) == 1
    assert str(out / "registered") in err  # the user's path, not a staging folder's
    assert not out.exists() and not [p for p in tmp_path.iterdir() if p.name.startswith(".out")]


def test_recording_given_as_its_manifest(tmp_path, capsys, monkeypatch):
    """--recording DIR/recording.json means DIR (as calibrate accepts SESSION/session.json),
    not 'recording folder not found' for a file that exists."""
    rig, rec = _write_inputs(tmp_path)
    monkeypatch.setattr(pipeline_mod, "Registrar", _FakeRegistrar)
    code = cli.main(_args(rig, rec / "recording.json", tmp_path / "out"))
    assert code == 0, capsys.readouterr().err
    assert _FakeRegistrar.seen["recording"].folder == rec


def test_recording_without_images_still_writes_cases(tmp_path, capsys):
    """A recording with only a depth map: no registered images, but case maps, areas and a point
    cloud (grey) -- not a StopIteration traceback from picking the colour camera."""
    rig, rec = _write_inputs(tmp_path)
    (rec / "recording.json").write_text(json.dumps({"depth": "depth.png", "images": {}}))
    out = tmp_path / "out"
    code = cli.main(_args(rig, rec, out))
    err = capsys.readouterr().err
    assert code == 0, err
    assert (out / "areas.png").is_file() and (out / "cases" / "thermal.png").is_file()
    assert not (out / "registered").exists()
    ply = PlyData.read(str(out / "pointcloud.ply"))
    assert ply["vertex"].count == H * W  # flat depth at 1 m, every ir ray hits


def test_bad_edge_angle(tmp_path, capsys):
    rig, rec = _write_inputs(tmp_path)
    assert cli.main(_args(rig, rec, tmp_path / "out", "ir", "--edge-angle", "95")) == 1
    assert "--edge-angle" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


def test_installed_script_reports_without_traceback(tmp_path):
    """One real process: the console script, a wrong image size."""
    rig, rec = _write_inputs(tmp_path)
    culprit = _wrong_size(tmp_path, rig, rec)[3]
    exe = Path(sys.executable).with_name("plantreg")
    assert exe.is_file(), f"console script not installed next to {sys.executable}"
    out = tmp_path / "out"
    p = subprocess.run([str(exe), *_args(rig, rec, out)], capture_output=True, text=True, timeout=120)
    assert p.returncode == 1
    assert str(culprit) in p.stderr and "32x24" in p.stderr
    assert "Traceback" not in p.stderr and "Traceback" not in p.stdout
    assert not out.exists()


# ---------------------------------------------------------------------- the good path, engine stubbed
class _FakeRegistrar:
    """Stands in for the engine: a result whose case counts are known (the CLI is under test)."""

    seen: dict = {}

    def __init__(self, rig, recording, params=None):
        _FakeRegistrar.seen = {"rig": rig, "recording": recording, "params": params}

    def register(self, target, progress=None, on_image=None):
        progress(0.5, "fake registration")
        _FakeRegistrar.seen["target"] = target
        rig = _FakeRegistrar.seen["rig"]
        cam = rig.camera(target)
        h, w = cam.shape
        o, d = cam.rays_rig()
        pts = (o + d / d[:, 2:3]).reshape(h, w, 3).astype(np.float32)
        pts[:, : w // 2] = np.nan                       # left half: background
        obj = np.isfinite(pts[..., 0])
        reg = {}
        cases = {}
        for c in rig.cameras:
            img = _FakeRegistrar.seen["recording"].images[c.name]
            shape = (h, w) + img.shape[2:]
            reg[c.name] = np.where(obj.reshape(obj.shape + (1,) * (len(shape) - 2)), 1.0, np.nan).astype(np.float32) * np.ones(shape, np.float32)
            if c.name != target:
                k = np.zeros((h, w), np.uint8)
                k[obj] = 1
                k[0, w // 2: w // 2 + 6] = 2   # 6 pixels P2
                cases[c.name] = k
        area = np.where(obj, 4, 6).astype(np.uint8)
        for c, img in reg.items():  # as the engine does: each image as soon as it is made
            if on_image is not None:
                on_image(c, img)
        return register_mod.RegistrationResult(target, pts, area, reg, {}, cases, self.seen["params"],
                                               timings={"raycast": 0.001})


def test_good_run_writes_the_folder_and_prints_case_shares(tmp_path, capsys, monkeypatch):
    rig, rec = _write_inputs(tmp_path)
    monkeypatch.setattr(pipeline_mod, "Registrar", _FakeRegistrar)
    out = tmp_path / "out"
    code = cli.main(["register", "--rig", str(rig), "--recording", str(rec), "--target", "thermal",
                     "--out", str(out), "--edge-angle", "20"])
    cap = capsys.readouterr()
    assert code == 0, cap.err
    assert _FakeRegistrar.seen["target"] == "thermal" and _FakeRegistrar.seen["params"].edge_angle_deg == 20.0
    assert isinstance(_FakeRegistrar.seen["recording"], Recording)
    assert "%]" in cap.err                     # progress lines without --quiet
    lines = cap.out.splitlines()
    assert "thermal" in lines[0] and "32x24" in lines[0]
    # 32 x 24 = 768 target pixels: half object (P1 384 - 6, P2 6), half background
    ir = next(s for s in lines if s.strip().startswith("ir:"))
    assert "P1  49.2%" in ir and "P2   0.8%" in ir and "P6  50.0%" in ir
    files = {str(p.relative_to(out)) for p in out.rglob("*") if p.is_file()}
    assert {"registered/thermal.tif", "registered/ir.tif", "registered/rgb.tif", "cases/ir.png",
            "cases/rgb.png", "areas.png", "pointcloud.ply", "mosaic.png", "summary.json"} <= files
    assert "cases/thermal.png" not in files
    s = json.loads((out / "summary.json").read_text())
    assert s["inputs"]["rig"] == str(rig.resolve()) and s["inputs"]["recording"] == str(rec.resolve())
    assert s["inputs"]["images"]["thermal"] == str((rec / "thermal.tif").resolve())
    assert "--edge-angle 20" in s["inputs"]["command"]
    assert s["parameters"]["edge_angle_deg"] == 20.0
    assert s["cases"]["ir"]["P2 occluded"]["pixels"] == 6
    # a second run onto the same folder needs --overwrite
    assert cli.main(_args(rig, rec, out, "thermal")) == 1
    assert cli.main(_args(rig, rec, out, "thermal", "--overwrite")) == 0


# ---------------------------------------------------------------------- end to end on the demo
def _run_main(argv):
    """cli.main in-process with stdout/stderr captured (usable from module-scoped fixtures)."""
    import contextlib
    import io

    o, e = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(o), contextlib.redirect_stderr(e):
        code = cli.main([str(a) for a in argv])
    return code, o.getvalue(), e.getvalue()


@pytest.fixture(scope="module")
def demo(tmp_path_factory):
    from plantreg_gui.core.synthetic import write_demo

    return write_demo(tmp_path_factory.mktemp("demo") / "demo", clean=True)


@pytest.fixture(scope="module")
def demo_ir(demo, tmp_path_factory):
    """`plantreg register` of the demo into the infrared (depth) camera."""
    out = tmp_path_factory.mktemp("reg") / "out_ir"
    code, so, se = _run_main(["register", "--rig", demo["rig"], "--recording", demo["recording"],
                              "--target", "ir", "--out", out])
    assert code == 0, se
    return out, so, se


def test_demo_output_layout_and_types(demo, demo_ir):
    from plantreg_gui.core.io.imageio import read_image

    out, so, se = demo_ir
    rig = Rig.load(demo["rig"])
    rec = Recording.load(demo["recording"], rig)
    H, W = rig.camera("ir").shape
    for cam in rig.cameras:
        with tifffile.TiffFile(out / f"registered/{cam.name}.tif") as t:
            assert len(t.pages) == 1
            a = t.asarray()
        assert a.dtype == np.float32 and a.shape == (H, W) + rec.images[cam.name].shape[2:]
        prev = cv2.imread(str(out / f"registered/{cam.name}.png"))
        assert prev.shape == (H, W, 3)
        if cam.name != "ir":
            c = read_image(out / f"cases/{cam.name}.png")
            assert c.dtype == np.uint8 and c.shape == (H, W) and c.max() <= 6
    assert not (out / "cases/ir.png").exists()
    assert read_image(out / "areas.png").shape == (H, W)
    assert cv2.imread(str(out / "mosaic.png")).shape == (H, W, 3)
    # the target registered into itself is its own raw image wherever mapped
    from plantreg_gui.core.synthetic import GroundTruth

    ir = tifffile.imread(out / "registered/ir.tif")
    m = np.isfinite(ir)
    obj = GroundTruth.load(demo["ground_truth"]).object
    assert (m & obj).sum() / (m | obj).sum() > 0.98   # mapped exactly where the true object is
    np.testing.assert_allclose(ir[m], rec.images["ir"][m].astype(np.float32), rtol=1e-3, atol=1.0)
    assert "%]" in se   # progress on stderr


def test_demo_pointcloud_is_the_true_surface(demo, demo_ir):
    import open3d as o3d

    from plantreg_gui.core.synthetic import GroundTruth

    out, _, _ = demo_ir
    gt = GroundTruth.load(demo["ground_truth"])
    v = PlyData.read(str(out / "pointcloud.ply"))["vertex"]
    pc = o3d.io.read_point_cloud(str(out / "pointcloud.ply"))
    assert len(pc.points) == v.count > 1000
    assert np.asarray(pc.colors).shape == (v.count, 3)
    rows, cols = np.asarray(v["row"]), np.asarray(v["col"])
    P = np.column_stack([v["x"], v["y"], v["z"]]).astype(np.float64)
    T = gt.points_rig[rows, cols]
    ok = np.isfinite(T).all(axis=1) & gt.object[rows, cols]
    assert ok.mean() > 0.9
    err = np.linalg.norm(P[ok] - T[ok], axis=1)
    assert np.median(err) < 0.002, np.median(err)   # millimetre-quantised depth
    names = {p.name for p in v.properties}
    assert {"ir", "thermal", "rgb_b000", "hyperspectral_b000", "thermal_case"} <= names


def test_demo_case_maps_agree_with_ground_truth_and_summary(demo, demo_ir):
    from plantreg_gui.core.io.imageio import read_image
    from plantreg_gui.core.synthetic import GroundTruth

    out, so, _ = demo_ir
    gt = GroundTruth.load(demo["ground_truth"])
    s = json.loads((out / "summary.json").read_text())
    assert s["target"] == "ir" and set(s["cases"]) == {"rgb", "thermal", "hyperspectral"}
    for src in ("rgb", "thermal", "hyperspectral"):
        c = read_image(out / f"cases/{src}.png")
        p1 = c == 1
        assert p1.sum() > 1000
        # a P1 pixel is one whose point the source truly sees (camera names not mixed up)
        assert gt.visible[src][p1].mean() > 0.97, (src, gt.visible[src][p1].mean())
        assert s["cases"][src]["P1 legitimate"]["pixels"] == int(p1.sum())
        line = next(s_ for s_ in so.splitlines() if s_.strip().startswith(f"{src}:"))
        assert f"P1 {100 * p1.mean():5.1f}%" in line
        tif = tifffile.imread(out / f"registered/{src}.tif")
        mapped = np.isfinite(tif) if tif.ndim == 2 else np.isfinite(tif).all(axis=2)
        assert np.all(mapped[p1])     # every legitimate pixel has a value
    assert s["inputs"]["rig"] == str(Path(demo["rig"]).resolve())


def test_demo_with_thermal_as_target(demo, tmp_path):
    rig = Rig.load(demo["rig"])
    rec = Recording.load(demo["recording"], rig)
    out = tmp_path / "out"
    code, so, se = _run_main(["register", "--rig", demo["rig"], "--recording", demo["recording"],
                              "--target", "thermal", "--out", out, "--quiet", "--edge-angle", "15"])
    assert code == 0, se
    assert se == ""   # --quiet
    th = tifffile.imread(out / "registered/thermal.tif")
    assert th.shape == (480, 640)
    m = np.isfinite(th)
    assert m.sum() > 10000
    np.testing.assert_allclose(th[m], rec.images["thermal"][m], atol=1e-3)
    assert (out / "cases/ir.png").exists() and not (out / "cases/thermal.png").exists()


def test_only_the_invoked_subcommand_is_built_and_help_lists_all(capsys):
    """``plantreg register ...`` imports and builds only register's parser (start-up of a
    pipeline step); ``plantreg --help`` and an unknown command still name every subcommand."""
    code = ("import sys; from plantreg_gui import cli; p = cli.build_parser(sys.argv[1:]); "
            "print(sorted(m.rsplit('.', 1)[1] for m in sys.modules if m.endswith('_cmd') and m.startswith('plantreg_gui.cli.')))")
    out = subprocess.run([sys.executable, "-c", code, "register", "--rig", "r.json"], capture_output=True, text=True,
                         check=True).stdout
    assert out.strip() == "['register_cmd']"
    out = subprocess.run([sys.executable, "-c", code, "fit-rig"], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "['fit_rig_cmd']"
    full = subprocess.run([sys.executable, "-c", code, "--help"], capture_output=True, text=True).stdout
    assert all(f"{m}_cmd" in full for m in cli.SUBCOMMANDS)
    with pytest.raises(SystemExit):
        cli.build_parser(["--help"]).parse_args(["--help"])
    helptext = capsys.readouterr().out
    for name in ("demo", "register", "calibrate", "fit-rig", "recording", "batch"):
        assert name in helptext
    # the lazily built parser parses register's arguments exactly as the full one
    argv = ["register", "--rig", "r.json", "--recording", "d", "--target", "ir", "--out", "o", "--outputs", "ply"]
    lazy, full_ns = cli.build_parser(argv).parse_args(argv), cli.build_parser().parse_args(argv)
    assert {k: v for k, v in vars(lazy).items()} == {k: v for k, v in vars(full_ns).items()}
    with pytest.raises(SystemExit):
        cli.build_parser(["fit_rig"]).parse_args(["fit_rig"])  # the module name is not a command
    assert "invalid choice: 'fit_rig'" in capsys.readouterr().err


@pytest.mark.parametrize("thread", [False, True])
def test_program_exit_keeps_output_code_and_exit_handlers(tmp_path, thread):
    """``cli.entry`` (the ``plantreg`` program) skips the interpreter's teardown, but the exit
    code, every line printed, the atexit handlers and a still-running non-daemon thread's work
    are kept."""
    code = f"""
import atexit, sys, threading, time
from pathlib import Path
from plantreg_gui import cli
out = Path({str(tmp_path)!r})
def fake_main():
    atexit.register(lambda: (out / "atexit").write_text("ran"))
    for i in range(20000):
        print(f"line {{i}}")
    print("partial", end="", file=sys.stderr)
    if {thread}:
        threading.Thread(target=lambda: (time.sleep(0.3), (out / "thread").write_text("done"))).start()
    return 3
cli.main = fake_main
cli.entry()
"""
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert p.returncode == 3
    assert p.stdout.splitlines() == [f"line {i}" for i in range(20000)]
    assert p.stderr == "partial"
    assert (tmp_path / "atexit").read_text() == "ran"
    assert (tmp_path / "thread").exists() == thread


def test_progress_lines_always_name_their_stage(capsys):
    from plantreg_gui.cli import StderrProgress

    p = StderrProgress()
    p(0.40, "sampling thermal")
    p(0.48, "")  # a step's own fraction without a label (sample_bilinear reports so)
    p(0.56, "classification hyperspectral")
    lines = capsys.readouterr().err.splitlines()
    assert lines == ["[ 40%] sampling thermal", "[ 48%] sampling thermal", "[ 56%] classification hyperspectral"]
    StderrProgress(quiet=True)(0.5, "x")
    assert capsys.readouterr().err == ""
