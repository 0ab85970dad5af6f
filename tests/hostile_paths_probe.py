"""Hostile pass of issue 22 (paths, names, outputs), as a script: every case runs in a fresh folder
under /tmp/hp/runs via `python -m plantreg_gui` with the given source tree on PYTHONPATH, and is
classified: clean (refused: non-zero exit, one line naming the path, no traceback, inputs
byte-unchanged, no leftovers), ok (a valid input, exit 0), MISHANDLED, VAGUE.

    python tests/hostile_paths_probe.py SOURCE_TREE [NAME_FILTER ...]

Outputs are only ever written under /tmp/hp/runs: device outputs are private nodes made there,
never /dev/null (an old version replaced the system's /dev/null with a file when run as root).
"""
import json, os, shutil, subprocess, sys, hashlib, stat, tempfile
from pathlib import Path
sys.path.insert(0, str(Path(__file__).resolve().parent))
SRC = sys.argv[1]
only = sys.argv[2:] 
os.environ["PYTHONPATH"] = SRC
sys.path.insert(0, SRC)
from test_hostile import _write_inputs, _manifest
import numpy as np, cv2, tifffile

PY = sys.executable


def _fixtures() -> None:
    """The calibration session and the landmark lab the cases copy (made once, with SRC's code)."""
    code = """
import sys, numpy as np
from pathlib import Path
sys.path.insert(0, %r)
from test_hostile import _K
from plantreg_gui.core.calibration.board import Board
from plantreg_gui.core.calibration.synthetic import write_calibration_session
from plantreg_gui.core.camera.camera import Camera
from plantreg_gui.core.camera.rig import Rig
from plantreg_gui.core.data.landmarks import LandmarkSet
from plantreg_gui.core.data.recording import Recording
from plantreg_gui.core.synthetic import demo_rig, make_plant_scene, render_depth
from plantreg_gui.core.synthetic.landmarks import perturb_rig, synthetic_landmarks
if not Path('/tmp/hp/session').exists():
    rig = Rig([Camera('ir', 'infrared', 320, 240, _K(300, 320, 240)), Camera('rgb', 'rgb', 320, 240, _K(320, 320, 240), t_cam_rig=[0.05, 0, 0])], depth_camera='ir', roi_min=[-1, -1, 0.2], roi_max=[1, 1, 1.5])
    write_calibration_session(rig, '/tmp/hp/session', n_poses=6, board=Board('chessboard', 9, 6, 0.04))
if not Path('/tmp/hp/fit').exists():
    root = Path('/tmp/hp/fit'); rig = demo_rig(); rng = np.random.default_rng(21); ls = LandmarkSet(base=root)
    for s in (51, 52):
        scene = make_plant_scene(s)
        Recording(None, render_depth(rig, scene), {}).save(root / 'recordings' / f'plant{s}')
        ls.recordings[f'recordings/plant{s}'] = synthetic_landmarks(rig, scene, 12, 0.7, rng)
    ls.save(root / 'landmarks.json'); perturb_rig(rig, rng).save(root / 'start.json')
""" % str(Path(__file__).resolve().parent)
    subprocess.run([PY, "-c", code], check=True, env=dict(os.environ, PYTHONPATH=SRC))
CASES = []
def case(expect="refuse", culprit=None):
    def deco(f):
        CASES.append((f.__name__, f, expect)); return f
    return deco

def reg(rig, rec, out, *extra):
    return ["register", "--rig", str(rig), "--recording", str(rec), "--target", "ir", "--out", str(out), "--quiet", *extra]

def lm(root, rec):
    return root / "landmarks.json"

def fit(rig, lmk, out, *extra):
    return ["fit-rig", "--rig", str(rig), "--landmarks", str(lmk), "--out", str(out), "--quiet", *extra]

def mkrec(root):
    rig, rec = _write_inputs(root); return rig, rec
def mkfit(root):
    for f in ("start.json", "landmarks.json"):
        shutil.copy(Path("/tmp/hp/fit") / f, root / f)
    shutil.copytree("/tmp/hp/fit/recordings", root / "recordings")
    return root / "start.json", root / "recordings" / "plant51"

# ------------------------------------------------------------------ fit-rig outputs
@case()
def fit_out_is_start_rig(r):
    rig, rec = mkfit(r); l = lm(r, rec); return fit(rig, l, rig, "--overwrite"), rig
@case()
def fit_out_is_manifest(r):
    rig, rec = mkfit(r); l = lm(r, rec); return fit(rig, l, rec / "recording.json", "--overwrite"), rec / "recording.json"
@case()
def fit_out_is_depth(r):
    rig, rec = mkfit(r); l = lm(r, rec); return fit(rig, l, rec / "depth.png", "--overwrite"), rec / "depth.png"
@case()
def fit_out_is_recording_folder(r):
    rig, rec = mkfit(r); l = lm(r, rec); return fit(rig, l, rec, "--overwrite"), rec
@case()
def fit_out_is_landmarks(r):
    rig, rec = mkfit(r); l = lm(r, rec); return fit(rig, l, l, "--overwrite"), l
@case()
def fit_out_is_symlink_to_rig(r):
    rig, rec = mkfit(r); l = lm(r, rec); os.symlink(rig, r / "ln.json"); return fit(rig, l, r / "ln.json", "--overwrite"), "ln.json"
@case()
def fit_out_empty(r):
    rig, rec = mkfit(r); l = lm(r, rec); return fit(rig, l, ""), "empty"
@case()
def fit_out_fifo(r):
    rig, rec = mkfit(r); l = lm(r, rec); os.mkfifo(r / "f.json"); return fit(rig, l, r / "f.json", "--overwrite"), r / "f.json"
@case()
def fit_out_dev_null(r):
    rig, rec = mkfit(r); l = lm(r, rec); os.mknod(r / "null", 0o666 | stat.S_IFCHR, os.makedev(1, 3)); return fit(rig, l, r / "null", "--overwrite"), r / "null"
@case()
def fit_out_loop(r):
    rig, rec = mkfit(r); l = lm(r, rec); os.symlink("loop.json", r / "loop.json"); return fit(rig, l, r / "loop.json", "--overwrite"), r / "loop.json"
@case()
def fit_out_parent_is_file(r):
    rig, rec = mkfit(r); l = lm(r, rec); (r / "afile").write_text("x"); return fit(rig, l, r / "afile" / "o.json"), r / "afile"
@case("ok" if os.geteuid() == 0 else "refuse")
def fit_out_readonly_folder(r):
    rig, rec = mkfit(r); l = lm(r, rec); (r / "ro").mkdir(); os.chmod(r / "ro", 0o555)
    return fit(rig, l, r / "ro" / "o.json"), r / "ro"
@case()
def fit_landmarks_loop(r):
    rig, rec = mkfit(r); os.symlink("l.json", r / "l.json"); return fit(rig, r / "l.json", r / "o.json"), r / "l.json"
@case()
def fit_landmarks_folder(r):
    rig, rec = mkfit(r); (r / "l.json").mkdir(); return fit(rig, r / "l.json", r / "o.json"), (r / "l.json", "folder")
@case()
def fit_landmarks_fifo(r):
    rig, rec = mkfit(r); os.mkfifo(r / "l.json"); return fit(rig, r / "l.json", r / "o.json"), (r / "l.json", "FIFO")
@case()
def fit_landmarks_dev_zero(r):
    rig, rec = mkfit(r); return fit(rig, "/dev/zero", r / "o.json"), ("/dev/zero", "device")
@case()
def fit_rig_loop(r):
    rig, rec = mkfit(r); l = lm(r, rec); os.symlink("s.json", r / "s.json"); return fit(r / "s.json", l, r / "o.json"), r / "s.json"
@case()
def fit_landmarks_one_spot(r):
    rig, rec = mkfit(r)
    d = json.loads((r / "landmarks.json").read_text()); p0 = d["recordings"]["recordings/plant51"]["points"][0]
    d["recordings"] = {"recordings/plant51": {"points": [p0] * 8}}
    (r / "landmarks.json").write_text(json.dumps(d)); return fit(rig, r / "landmarks.json", r / "o.json"), r / "landmarks.json"
@case()
def fit_landmarks_no_pairs(r):
    rig, rec = mkfit(r)
    d = json.loads((r / "landmarks.json").read_text())
    for k in d["recordings"]:
        for p_ in d["recordings"][k]["points"]: p_["cameras"] = {}
    (r / "landmarks.json").write_text(json.dumps(d)); return fit(rig, r / "landmarks.json", r / "o.json"), r / "landmarks.json"
@case()
def fit_out_long_name(r):
    rig, rec = mkfit(r); l = lm(r, rec); return fit(rig, l, r / ("x" * 300 + ".json")), "x" * 40

# ------------------------------------------------------------------ recording create
def rc(d, *extra):
    return ["recording", "create", str(d), *extra]
def _imgs(r):
    cv2.imwrite(str(r / "depth.png"), np.full((30, 40), 1000, np.uint16))
    cv2.imwrite(str(r / "ir.png"), np.full((30, 40), 9, np.uint8))
for nm, bad in [("dotdot", "../x"), ("slash", "a/b"), ("long65", "c" * 65), ("tab", "a\tb"), ("star", "th*"), ("qmark", "th?"),
                ("dotfile", ".hidden"), ("backslash", "a\\b"), ("colon", "a:b"), ("lead_space", " ir"), ("nonascii_nfd", "the\u0301rmal")]:
    def f(r, bad=bad):
        _imgs(r); return rc(r / "rec", "--depth", str(r / "depth.png"), "--image", f"{bad}={r / 'ir.png'}"), "camera"
    f.__name__ = f"rc_name_{nm}"; case()(f)
@case()
def rc_name_case_clash(r):
    _imgs(r); return rc(r / "rec", "--image", f"ir={r / 'ir.png'}", "--image", f"IR={r / 'ir.png'}"), "IR"
@case()
def rc_name_stem_clash(r):
    _imgs(r); return rc(r / "rec", "--image", f"a b={r / 'ir.png'}", "--image", f"a_b={r / 'ir.png'}"), "a_b"
@case()
def rc_dir_empty(r):
    _imgs(r); return rc("", "--depth", str(r / "depth.png")), "empty"
@case()
def rc_dir_loop(r):
    _imgs(r); os.symlink("rec", r / "rec"); return rc(r / "rec", "--depth", str(r / "depth.png")), r / "rec"
@case()
def rc_manifest_is_folder(r):
    _imgs(r); (r / "rec" / "recording.json").mkdir(parents=True); return rc(r / "rec", "--depth", str(r / "depth.png"), "--overwrite"), r / "rec"
@case()
def rc_manifest_is_fifo(r):
    _imgs(r); (r / "rec").mkdir(); os.mkfifo(r / "rec" / "recording.json"); return rc(r / "rec", "--depth", str(r / "depth.png"), "--overwrite"), r / "rec"
@case()
def rc_manifest_loop(r):
    _imgs(r); (r / "rec").mkdir(); os.symlink("recording.json", r / "rec" / "recording.json"); return rc(r / "rec", "--depth", str(r / "depth.png"), "--overwrite"), r / "rec"
@case()
def rc_image_loop(r):
    _imgs(r); os.symlink("x.png", r / "x.png"); return rc(r / "rec", "--image", f"ir={r / 'x.png'}"), r / "x.png"
@case()
def rc_depth_folder(r):
    _imgs(r); (r / "d.png").mkdir(); return rc(r / "rec", "--depth", str(r / "d.png")), (r / "d.png", "folder")
@case()
def rc_depth_devzero(r):
    _imgs(r); return rc(r / "rec", "--depth", "/dev/zero"), "/dev/zero"
@case()
def rc_depth_is_the_manifest(r):
    rig, rec = mkrec(r); return rc(rec, "--depth", str(rec / "recording.json"), "--overwrite"), rec / "recording.json"
@case()
def rc_dir_parent_file(r):
    _imgs(r); (r / "afile").write_text("x"); return rc(r / "afile" / "rec", "--depth", str(r / "depth.png")), r / "afile"
@case("ok" if os.geteuid() == 0 else "refuse")
def rc_dir_readonly(r):
    _imgs(r); (r / "ro").mkdir(); os.chmod(r / "ro", 0o555); return rc(r / "ro", "--depth", str(r / "depth.png")), r / "ro"
@case()
def rc_dir_is_devnull(r):
    _imgs(r); os.mknod(r / "null", 0o666 | stat.S_IFCHR, os.makedev(1, 3)); return rc(r / "null", "--depth", str(r / "depth.png"), "--overwrite"), r / "null"
@case("ok")
def rc_valid_space_name(r):
    _imgs(r); return rc(r / "rec", "--depth", str(r / "depth.png"), "--image", f"ir cam={r / 'ir.png'}"), None

# ------------------------------------------------------------------ register
@case()
def reg_recording_loop(r):
    rig, rec = mkrec(r); os.symlink("L", r / "L"); return reg(rig, r / "L", r / "out"), r / "L"
@case()
def reg_out_loop(r):
    rig, rec = mkrec(r); os.symlink("L", r / "L"); return reg(rig, rec, r / "L"), r / "L"
@case()
def reg_out_loop_overwrite(r):
    rig, rec = mkrec(r); os.symlink("L", r / "L"); return reg(rig, rec, r / "L", "--overwrite"), r / "L"
@case()
def reg_rig_loop(r):
    rig, rec = mkrec(r); os.symlink("L", r / "L"); return reg(r / "L", rec, r / "out"), r / "L"
@case()
def reg_nul_image(r):
    rig, rec = mkrec(r); _manifest(rec, thermal="the\u0000rmal.tif"); return reg(rig, rec, r / "out"), "recording.json"
@case()
def reg_nul_depth(r):
    rig, rec = mkrec(r); _manifest(rec, depth="dep\u0000th.png"); return reg(rig, rec, r / "out"), "recording.json"
@case()
def reg_image_loop(r):
    rig, rec = mkrec(r); os.symlink("t.tif", rec / "t.tif"); _manifest(rec, thermal="t.tif"); return reg(rig, rec, r / "out"), rec / "t.tif"
@case()
def reg_image_dir(r):
    rig, rec = mkrec(r); (rec / "t.tif").mkdir(); _manifest(rec, thermal="t.tif"); return reg(rig, rec, r / "out"), (rec / "t.tif", "folder")
@case()
def reg_empty_tiff(r):
    rig, rec = mkrec(r); (rec / "thermal.tif").write_bytes(b""); return reg(rig, rec, r / "out"), (rec / "thermal.tif", "empty")
@case()
def reg_thermal_edge(r):
    rig, rec = mkrec(r)
    d = json.loads(rig.read_text()); c = dict(d["cameras"][1]); c["name"] = "thermal_edge"; d["cameras"].append(c); rig.write_text(json.dumps(d))
    _manifest(rec, thermal_edge="thermal.tif"); return reg(rig, rec, r / "out"), "thermal_edge"
@case()
def reg_out_dot_empty_cwd(r):
    rig, rec = mkrec(r); (r / "cwd").mkdir(); return reg(rig, rec, "."), "."
@case()
def reg_out_is_recording(r):
    rig, rec = mkrec(r); return reg(rig, rec, rec, "--overwrite"), rec
@case()
def reg_out_contains_rig(r):
    rig, rec = mkrec(r); return reg(rig, rec, r, "--overwrite"), r
@case()
def reg_out_is_image_outside(r):
    rig, rec = mkrec(r); (r / "imgs").mkdir(); shutil.move(rec / "thermal.tif", r / "imgs" / "thermal.tif")
    _manifest(rec, thermal="../imgs/thermal.tif"); return reg(rig, rec, r / "imgs", "--overwrite"), r / "imgs"
@case()
def reg_out_fifo(r):
    rig, rec = mkrec(r); os.mkfifo(r / "o"); return reg(rig, rec, r / "o", "--overwrite"), r / "o"
@case()
def reg_out_devnull(r):
    rig, rec = mkrec(r); os.mknod(r / "null", 0o666 | stat.S_IFCHR, os.makedev(1, 3)); return reg(rig, rec, r / "null", "--overwrite"), r / "null"
@case("ok")
def reg_out_long250(r):
    rig, rec = mkrec(r); return reg(rig, rec, r / ("o" * 250)), None
@case()
def reg_out_long300(r):
    rig, rec = mkrec(r); return reg(rig, rec, r / ("o" * 300)), "o" * 30
@case()
def reg_out_parent_file(r):
    rig, rec = mkrec(r); (r / "afile").write_text("x"); return reg(rig, rec, r / "afile" / "o"), r / "afile"
@case("ok" if os.geteuid() == 0 else "refuse")
def reg_out_readonly(r):
    rig, rec = mkrec(r); (r / "ro").mkdir(); os.chmod(r / "ro", 0o555); return reg(rig, rec, r / "ro" / "o"), r / "ro"
@case()
def reg_recording_fifo(r):
    rig, rec = mkrec(r); os.mkfifo(r / "fifo"); return reg(rig, r / "fifo", r / "out"), r / "fifo"
@case()
def reg_recording_devzero(r):
    rig, rec = mkrec(r); return reg(rig, "/dev/zero", r / "out"), "/dev/zero"
@case()
def reg_manifest_loop(r):
    rig, rec = mkrec(r); (rec / "recording.json").unlink(); os.symlink("recording.json", rec / "recording.json"); return reg(rig, rec, r / "out"), rec / "recording.json"
@case()
def reg_manifest_folder(r):
    rig, rec = mkrec(r); (rec / "recording.json").unlink(); (rec / "recording.json").mkdir(); return reg(rig, rec, r / "out"), rec / "recording.json"
@case()
def reg_rig_name_star(r):
    rig, rec = mkrec(r); d = json.loads(rig.read_text()); d["cameras"][1]["name"] = "therm*"; rig.write_text(json.dumps(d)); _manifest(rec); m = json.loads((rec / "recording.json").read_text()); m["images"]["therm*"] = m["images"].pop("thermal"); (rec / "recording.json").write_text(json.dumps(m)); return reg(rig, rec, r / "out"), rig
@case()
def reg_rig_name_nonascii_nfc_nfd(r):
    rig, rec = mkrec(r); d = json.loads(rig.read_text()); d["cameras"][1]["name"] = "w\u00e4rme"; d["cameras"][2]["name"] = "wa\u0308rme"; rig.write_text(json.dumps(d)); m = json.loads((rec / "recording.json").read_text()); m["images"]["w\u00e4rme"] = m["images"].pop("thermal"); m["images"]["wa\u0308rme"] = m["images"].pop("rgb"); (rec / "recording.json").write_text(json.dumps(m)); return reg(rig, rec, r / "out"), rig
@case("ok")
def reg_envi_sibling_folder(r):
    rig, rec = mkrec(r)
    d = json.loads(rig.read_text()); c = dict(d["cameras"][1]); c["name"] = "hyperspectral"; c["modality"] = "hyperspectral"; d["cameras"].append(c); rig.write_text(json.dumps(d))
    import spectral.io.envi as envi
    envi.save_image(str(rec / "hyperspectral.hdr"), np.ones((24, 32, 5), np.float32), force=True, interleave="bsq", ext=".img")
    (rec / "hyperspectral").mkdir()
    _manifest(rec, hyperspectral="hyperspectral.hdr"); return reg(rig, rec, r / "out"), None
@case("ok")
def reg_valid(r):
    rig, rec = mkrec(r); return reg(rig, rec, r / "out"), None
@case()
def reg_stdout_closed(r):
    rig, rec = mkrec(r); return reg(rig, rec, r / "out") + ["__CLOSE_STDOUT__"], "standard output"
@case()
def reg_stdout_devfull(r):
    rig, rec = mkrec(r); return reg(rig, rec, r / "out") + ["__DEVFULL__"], "standard output"
@case()
def reg_ulimit_v(r):
    rig, rec = mkrec(r); return reg(rig, rec, r / "out") + ["__ULIMIT__"], "memory"

# ------------------------------------------------------------------ batch
def bat(rig, out, *recs):
    return ["batch", "--rig", str(rig), "--target", "ir", "--out", str(out), "--workers", "1", "--quiet", *map(str, recs)]
@case()
def batch_list_nul(r):
    rig, rec = mkrec(r); (r / "list.txt").write_text(f"{rec}\nre\u0000c\n"); return bat(rig, r / "out", r / "list.txt"), "list.txt"
@case()
def batch_rec_loop(r):
    rig, rec = mkrec(r); os.symlink("L", r / "L"); return bat(rig, r / "out", r / "L"), r / "L"
@case()
def batch_out_loop(r):
    rig, rec = mkrec(r); os.symlink("L", r / "L"); return bat(rig, r / "L", rec), r / "L"
@case()
def batch_rec_fifo(r):
    rig, rec = mkrec(r); os.mkfifo(r / "F"); return bat(rig, r / "out", r / "F"), r / "F"
@case()
def batch_rec_devzero(r):
    rig, rec = mkrec(r); return bat(rig, r / "out", "/dev/zero"), "/dev/zero"
@case()
def batch_out_is_rec(r):
    rig, rec = mkrec(r); return bat(rig, rec, rec), rec
@case()
def batch_out_empty_parent_file(r):
    rig, rec = mkrec(r); (r / "afile").write_text("x"); return bat(rig, r / "afile" / "o", rec), r / "afile"

# ------------------------------------------------------------------ calibrate / demo
@case()
def cal_out_loop(r):
    s = Path("/tmp/hp/session"); shutil.copytree(s, r / "s"); os.symlink("L", r / "L")
    return ["calibrate", str(r / "s"), "--out", str(r / "L"), "--report", str(r / "rep.json"), "--quiet"], r / "L"
@case()
def cal_out_is_session_json(r):
    s = Path("/tmp/hp/session"); shutil.copytree(s, r / "s")
    return ["calibrate", str(r / "s"), "--out", str(r / "s" / "session.json"), "--report", str(r / "rep.json"), "--quiet", "--overwrite"], "session.json"
@case()
def cal_out_fifo(r):
    s = Path("/tmp/hp/session"); shutil.copytree(s, r / "s"); os.mkfifo(r / "o.json")
    return ["calibrate", str(r / "s"), "--out", str(r / "o.json"), "--report", str(r / "rep.json"), "--quiet", "--overwrite"], r / "o.json"
@case()
def demo_loop(r):
    os.symlink("L", r / "L"); return ["demo", str(r / "L"), "--quiet"], r / "L"
@case()
def demo_dot(r):
    (r / "cwd").mkdir(); return ["demo", ".", "--quiet"], "."


# ------------------------------------------------------------------ own pass: new classes
@case()
def own_out_parent_fifo(r):
    rig, rec = mkrec(r); os.mkfifo(r / "F"); return reg(rig, rec, r / "F" / "out"), r / "F"
@case()
def own_out_trailing_slash_file(r):
    rig, rec = mkrec(r); (r / "afile").write_text("x"); return reg(rig, rec, str(r / "afile") + "/", "--overwrite"), "afile"
@case("ok")
def own_out_dangling_link(r):
    rig, rec = mkrec(r); os.symlink("nowhere", r / "dl"); return reg(rig, rec, r / "dl"), None
@case()
def own_image_dangling_link(r):
    rig, rec = mkrec(r); os.symlink("nowhere.tif", rec / "t.tif"); _manifest(rec, thermal="t.tif"); return reg(rig, rec, r / "out"), rec / "t.tif"
@case()
def own_rig_is_folder(r):
    rig, rec = mkrec(r); (r / "rigdir").mkdir(); return reg(r / "rigdir", rec, r / "out"), (r / "rigdir", "folder")
@case()
def own_recording_manifest_fifo_given(r):
    rig, rec = mkrec(r); (rec / "recording.json").unlink(); os.mkfifo(rec / "recording.json"); return reg(rig, rec / "recording.json", r / "out"), "recording.json"
@case()
def own_batch_out_fifo(r):
    rig, rec = mkrec(r); os.mkfifo(r / "F"); return bat(rig, r / "F", rec), r / "F"
@case()
def own_cal_report_loop(r):
    s = Path("/tmp/hp/session"); shutil.copytree(s, r / "s"); os.symlink("L.json", r / "L.json")
    return ["calibrate", str(r / "s"), "--out", str(r / "o.json"), "--report", str(r / "L.json"), "--quiet", "--overwrite"], r / "L.json"
@case()
def own_cal_report_fifo(r):
    s = Path("/tmp/hp/session"); shutil.copytree(s, r / "s"); os.mkfifo(r / "R.json")
    return ["calibrate", str(r / "s"), "--out", str(r / "o.json"), "--report", str(r / "R.json"), "--quiet", "--overwrite"], r / "R.json"
@case()
def own_demo_fifo(r):
    os.mkfifo(r / "F"); return ["demo", str(r / "F"), "--quiet", "--overwrite"], r / "F"
@case()
def own_fit_recording_loop(r):
    rig, rec = mkfit(r); os.symlink("L", r / "L"); return fit(rig, r / "landmarks.json", r / "o.json", "--refine", "--recording", str(r / "L")), r / "L"
@case()
def own_rc_dir_dangling_link(r):
    _imgs(r); os.symlink("nowhere", r / "dl"); return rc(r / "dl", "--depth", str(r / "depth.png")), r / "dl"
@case()
def own_rc_depth_nonexistent(r):
    _imgs(r); return rc(r / "rec", "--depth", str(r / "nope.png")), r / "nope.png"
@case()
def own_rc_windows_device_name(r):
    _imgs(r); return rc(r / "rec", "--image", f"CON={r / 'ir.png'}"), "CON"
@case()
def own_batch_nfc_nfd_folders(r):
    rig, rec = mkrec(r); a = r / "\u00c4rger"; b = r / "A\u0308rger"; shutil.copytree(rec, a); shutil.copytree(rec, b)
    return bat(rig, r / "out", a, b), "clash"
@case()
def own_out_under_proc(r):
    rig, rec = mkrec(r); return reg(rig, rec, "/proc/plantreg_out"), "/proc/plantreg_out"
@case("ok")
def own_out_deep_new_parents(r):
    rig, rec = mkrec(r); return reg(rig, rec, r / "a" / "b" / "c" / "out"), None
@case()
def own_image_is_socket(r):
    import socket
    rig, rec = mkrec(r); s_ = socket.socket(socket.AF_UNIX); s_.bind(str(rec / "t.tif")); _manifest(rec, thermal="t.tif"); return reg(rig, rec, r / "out"), (rec / "t.tif", "socket")
@case()
def own_fit_out_is_landmark_recording_image_via_dotdot(r):
    rig, rec = mkfit(r); return fit(rig, r / "landmarks.json", str(rec) + "/../plant51/depth.png", "--overwrite"), "depth.png"

def snapshot(root):
    out = {}
    for dp, dn, fn in os.walk(root):
        for f in fn:
            p = Path(dp) / f
            try:
                st = os.lstat(p)
                if stat.S_ISREG(st.st_mode):
                    out[str(p)] = hashlib.md5(p.read_bytes()).hexdigest()
                else:
                    out[str(p)] = stat.S_IFMT(st.st_mode)
            except OSError:
                out[str(p)] = "?"
    return out

def run_case(name, f, expect):
    r = Path(tempfile.mkdtemp(prefix="hp_", dir="/tmp/hp/runs"))
    argv, culprit = f(r)
    cwd = r / "cwd" if (r / "cwd").is_dir() else r
    before = snapshot(r)
    stdout = subprocess.PIPE; pre = None; shell_prefix = None
    if "__CLOSE_STDOUT__" in argv:
        argv.remove("__CLOSE_STDOUT__"); stdout = "close"
    if "__DEVFULL__" in argv:
        argv.remove("__DEVFULL__"); stdout = open("/dev/full", "w")
    if "__ULIMIT__" in argv:
        argv.remove("__ULIMIT__")
        import resource
        pre = lambda: resource.setrlimit(resource.RLIMIT_AS, (900000 * 1024, 900000 * 1024))
    cmd = [PY, "-m", "plantreg_gui", *argv]
    if stdout == "close":
        import shlex
        p = subprocess.run(["bash", "-c", " ".join(map(shlex.quote, cmd)) + " >&-"], stderr=subprocess.PIPE, text=True, cwd=cwd, timeout=300)
        out = ""
    else:
        p = subprocess.run(cmd, stdout=stdout, stderr=subprocess.PIPE, text=True, cwd=cwd, timeout=300, preexec_fn=pre)
        out = p.stdout or ""
    err = p.stderr + ("" if argv[0] != "batch" else (p.stdout or ""))
    after = snapshot(r)
    changed = [k for k in before if after.get(k) != before[k]]
    added = [k for k in after if k not in before]
    leftovers = [k for k in added if ".part" in k or ".old" in k or ".plantreg-probe" in k]
    # also leftovers in /tmp/hp/runs beside? and in cwd
    problems = []
    if "Traceback" in err or "Exception ignored" in err:
        problems.append("traceback")
    if expect == "ok":
        verdict = "ok" if p.returncode == 0 and not problems else "MISHANDLED"
    else:
        if p.returncode == 0:
            problems.append("exit 0")
        if changed:
            problems.append(f"inputs changed {[os.path.relpath(c, r) for c in changed]}")
        if leftovers:
            problems.append(f"leftovers {[os.path.relpath(c, r) for c in leftovers]}")
        lines = [l for l in err.strip().splitlines() if l.strip()]
        verdict = "MISHANDLED" if problems else "clean"
        if not problems:
            words = culprit if isinstance(culprit, tuple) else (culprit,)
            need = [str(w) for w in words if w is not None]
            # names relative ok: check basename
            miss = [w for w in need if w not in err and Path(w).name not in err]
            if p.returncode == 2 and "must not be empty" in err:
                lines, miss = lines[-1:], []  # argparse's usage + one error line, exit 2 (the convention)
            if len(lines) != 1 or miss or ".part" in err or "XXXX" in err:
                verdict = "VAGUE"
    shutil.rmtree(r, ignore_errors=True)
    if os.path.exists(r):
        subprocess.run(["chmod", "-R", "u+w", str(r)]); shutil.rmtree(r, ignore_errors=True)
    return verdict, p.returncode, (problems, err.strip()[-300:])

if __name__ == "__main__":
    Path("/tmp/hp/runs").mkdir(parents=True, exist_ok=True)
    _fixtures()
    counts = {}
    for name, f, expect in CASES:
        if only and not any(o in name for o in only):
            continue
        try:
            v, rc_, info = run_case(name, f, expect)
        except Exception as e:
            v, rc_, info = "PROBE-ERROR", None, repr(e)
        counts[v] = counts.get(v, 0) + 1
        print(f"{v:11s} {name:32s} rc={rc_} {info if v not in ('clean','ok') else ''}", flush=True)
    print("TOTAL", sum(counts.values()), counts)
