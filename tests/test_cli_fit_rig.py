"""`plantreg fit-rig` and `plantreg recording create` from the command line."""

import json
import subprocess
import sys

import cv2
import numpy as np
import pytest
import tifffile

from plantreg_gui import cli
from plantreg_gui.core.camera.camera import Camera
from plantreg_gui.core.data.landmarks import LandmarkSet
from plantreg_gui.core.data.recording import Recording
from plantreg_gui.core.camera.rig import Rig
from plantreg_gui.core.synthetic import demo_rig, make_plant_scene, render_depth
from plantreg_gui.core.synthetic.landmarks import perturb_rig, synthetic_landmarks


@pytest.fixture(scope="module")
def fit_inputs(tmp_path_factory):
    """Two recordings (depth only) of the demo rig with 12 noisy landmarks each, a start rig off
    by 3 degrees / 3 cm / 3 % focal, and the true rig."""
    root = tmp_path_factory.mktemp("fit")
    rig = demo_rig()
    rng = np.random.default_rng(21)
    ls = LandmarkSet(base=root)
    for s in (51, 52):
        scene = make_plant_scene(s)
        Recording(None, render_depth(rig, scene), {}).save(root / "recordings" / f"plant{s}")
        ls.recordings[f"recordings/plant{s}"] = synthetic_landmarks(rig, scene, 12, 0.7, rng)
    ls.save(root / "landmarks.json")
    perturb_rig(rig, rng).save(root / "start.json")
    return root, rig


def _run(argv, capsys):
    code = cli.main(argv)
    out, err = capsys.readouterr()
    return code, out, err


def test_fit_rig_writes_a_rig_with_provenance(fit_inputs, tmp_path, capsys):
    root, true = fit_inputs
    out = tmp_path / "fitted.json"
    code, stdout, err = _run(["fit-rig", "--rig", str(root / "start.json"), "--landmarks", str(root / "landmarks.json"),
                              "--out", str(out), "--free", "rgb:focal,thermal:focal,hyperspectral:focal"], capsys)
    assert code == 0, err
    for cam in ("rgb", "thermal", "hyperspectral"):
        assert cam in stdout
    assert "worst landmarks" in stdout and "LOO median" in stdout
    rig = Rig.load(out)
    cal = rig.extra["calibration"]
    assert cal["method"] == "landmarks" and cal["landmarks_used"] == 24
    assert len(cal["residuals"]) == 72
    r = [d["residual_px"] for d in cal["residuals"]]
    assert r == sorted(r, reverse=True)  # worst first
    assert set(cal["leave_one_out"]["per_recording"]) == {"recordings/plant51", "recordings/plant52"}
    assert "fit-rig" in cal["command"]
    # the fit moved the cameras back to within a few mm of the truth (from 3 cm off)
    for cam in ("rgb", "thermal", "hyperspectral"):
        assert np.linalg.norm(rig.camera(cam).center_rig - true.camera(cam).center_rig) < 0.015, cam
    # never overwritten silently
    code, _, err = _run(["fit-rig", "--rig", str(root / "start.json"), "--landmarks", str(root / "landmarks.json"),
                         "--out", str(out)], capsys)
    assert code == 1 and "--overwrite" in err and str(out) in err
    before = out.read_text()
    code, _, err = _run(["fit-rig", "--rig", str(root / "start.json"), "--landmarks", str(root / "landmarks.json"),
                         "--out", str(out), "--overwrite"], capsys)
    assert code == 0 and out.read_text() != before  # another date and no free focal


@pytest.mark.parametrize("breakit, words", [
    (lambda d: d.update(format="x"), "expected 'plantreg.landmarks'"),
    (lambda d: d["recordings"].update({"recordings/nope": {"points": [{"depth_uv": [1, 1], "cameras": {}}]}}),
     "'recordings/nope' does not exist"),
    (lambda d: d["recordings"]["recordings/plant51"]["points"][0]["cameras"].update(nir=[1, 2]), "unknown camera 'nir'"),
])
def test_fit_rig_bad_landmarks_one_line(fit_inputs, tmp_path, capsys, breakit, words):
    root, _ = fit_inputs
    d = json.loads((root / "landmarks.json").read_text())
    breakit(d)
    bad = root / "bad_landmarks.json"  # beside the recordings: their paths are relative to it
    bad.write_text(json.dumps(d))
    out = tmp_path / "rig.json"
    code, stdout, err = _run(["fit-rig", "--rig", str(root / "start.json"), "--landmarks", str(bad),
                              "--out", str(out)], capsys)
    assert code == 1 and words in err and str(bad) in err, err
    assert err.count("\n") == 1 and "Traceback" not in err
    assert not out.exists()


def test_fit_rig_degenerate_and_options(fit_inputs, tmp_path, capsys):
    root, _ = fit_inputs
    base = ["fit-rig", "--rig", str(root / "start.json"), "--landmarks", str(root / "landmarks.json"),
            "--out", str(tmp_path / "r.json")]
    code, _, err = _run(base + ["--free", "zoom"], capsys)
    assert code == 1 and "cannot free 'zoom'" in err
    code, _, err = _run(base + ["--recording", str(root)], capsys)
    assert code == 1 and "--refine" in err
    # too few landmarks for everything freed
    d = json.loads((root / "landmarks.json").read_text())
    for r in d["recordings"].values():
        r["points"] = r["points"][:2]
    few = root / "few.json"
    few.write_text(json.dumps(d))
    code, _, err = _run(base[:4] + [str(few)] + base[5:], capsys)
    assert code == 1 and "needs at least" in err and "Traceback" not in err


def test_fit_rig_subprocess_has_no_traceback(fit_inputs, tmp_path):
    root, _ = fit_inputs
    p = subprocess.run([sys.executable, "-c", "import sys; from plantreg_gui.cli import main; sys.exit(main())",
                        "fit-rig", "--rig", str(root / "start.json"), "--landmarks", str(tmp_path / "none.json"),
                        "--out", str(tmp_path / "o.json")], capture_output=True, text=True)
    assert p.returncode == 1 and "landmarks file is missing (not found)" in p.stderr and "Traceback" not in p.stderr


# ---------------------------------------------------------------------------- recording create
W, H = 40, 30


def _lab(tmp_path):
    """A tiny rig and a lab's files under their own names, elsewhere than the recording folder."""
    K = lambda f, w, h: [[f, 0, (w - 1) / 2], [0, f, (h - 1) / 2], [0, 0, 1]]  # noqa: E731
    cams = [Camera("ir", "infrared", W, H, K(40, W, H)),
            Camera("thermal", "thermal", 32, 24, K(30, 32, 24), t_cam_rig=[0.05, 0, 0]),
            Camera("rgb", "rgb", 80, 60, K(80, 80, 60), t_cam_rig=[-0.05, 0, 0])]
    rig = Rig(cams, depth_camera="ir", roi_min=[-1, -1, 0.2], roi_max=[1, 1, 1.5])
    rig.save(tmp_path / "rig.json")
    lab = tmp_path / "lab data" / "2024-05-01"
    lab.mkdir(parents=True)
    cv2.imwrite(str(lab / "DEPTH_0001.png"), np.full((H, W), 2000, np.uint16))
    np.save(lab / "IR_0001.npy", np.random.default_rng(0).integers(0, 4000, (H, W)).astype(np.uint16))
    tifffile.imwrite(lab / "TH_0001.tiff", np.full((24, 32), 21.5, np.float32))
    cv2.imwrite(str(lab / "RGB_0001.png"), np.full((60, 80, 3), 90, np.uint8))
    return tmp_path / "rig.json", lab


def test_recording_create_round_trip_and_register(tmp_path, capsys):
    rig, lab = _lab(tmp_path)
    rec = tmp_path / "recordings" / "p1"
    code, out, err = _run(["recording", "create", str(rec), "--depth", str(lab / "DEPTH_0001.png"),
                           "--depth-scale", "0.0005", "--image", f"ir={lab / 'IR_0001.npy'}",
                           "--image", f"thermal={lab / 'TH_0001.tiff'}", "--image", f"rgb={lab / 'RGB_0001.png'}"],
                          capsys)
    assert code == 0, err
    m = json.loads((rec / "recording.json").read_text())
    assert m["depth"] == "../../lab data/2024-05-01/DEPTH_0001.png"  # relative to the folder, nothing copied
    assert sorted(rec.iterdir()) == [rec / "recording.json"]
    r = Recording.load(rec, Rig.load(rig))
    assert np.array_equal(r.images["ir"], np.load(lab / "IR_0001.npy"))
    assert np.allclose(r.depth_m(0.001), 1.0)  # 2000 units x 0.5 mm (the recording's own scale)
    code, out, err = _run(["register", "--rig", str(rig), "--recording", str(rec), "--target", "ir",
                           "--out", str(tmp_path / "out"), "--quiet"], capsys)
    assert code == 0, err
    assert (tmp_path / "out").is_dir()
    # existing recording.json: refused unless --overwrite
    argv = ["recording", "create", str(rec), "--depth", str(lab / "DEPTH_0001.png")]
    code, _, err = _run(argv, capsys)
    assert code == 1 and "--overwrite" in err
    code, _, err = _run(argv + ["--overwrite"], capsys)
    assert code == 0 and json.loads((rec / "recording.json").read_text()) == {"depth": m["depth"], "images": {}}


@pytest.mark.parametrize("make, words", [
    (lambda lab: ["--image", f"ir={lab / 'missing.png'}"], "not found"),
    (lambda lab: ["--image", f"ir={lab / 'notes.png'}"], "not a PNG file"),
    (lambda lab: ["--image", "ir"], "NAME=FILE"),
    (lambda lab: ["--image", f"ir={lab / 'IR_0001.npy'}", "--image", f"ir={lab / 'IR_0001.npy'}"], "given twice"),
    (lambda lab: ["--depth", str(lab / "RGB_0001.png")], "single-channel"),
    (lambda lab: ["--depth", str(lab / "DEPTH_0001.png"), "--depth-scale", "-1"], "--depth-scale"),
    (lambda lab: [], "--depth FILE"),
])
def test_recording_create_bad_input(tmp_path, capsys, make, words):
    _rig, lab = _lab(tmp_path)
    (lab / "notes.png").write_text("not an image")
    rec = tmp_path / "rec"
    code, _, err = _run(["recording", "create", str(rec)] + make(lab), capsys)
    assert code == 1 and words in err and err.count("\n") == 1, err
    assert not (rec / "recording.json").exists()


def test_recording_json_depth_scale_is_checked(tmp_path):
    rec = tmp_path / "r"
    rec.mkdir()
    (rec / "recording.json").write_text(json.dumps({"images": {}, "depth_scale": "mm"}))
    with pytest.raises(Exception, match="depth_scale must be a number"):
        Recording.load(rec)
