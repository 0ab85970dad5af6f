"""Hostile pass of issue 22 (paths, names, outputs), as a script: every case runs in a fresh folder
under /tmp/hp/runs via `python -m plantreg_gui` with the given source tree on PYTHONPATH, and is
classified: clean (refused: non-zero exit, one line naming the path, no traceback, inputs
byte-unchanged, no leftovers), ok (a valid input, exit 0), MISHANDLED, VAGUE.

    python tests/hostile_paths_probe.py SOURCE_TREE [NAME_FILTER ...]   (HP_ROOT=/tmp/hp by default)

Classes: outputs over inputs and special files, camera names, symlink loops, NUL bytes (round 3,
108 inputs); and, generated (round 3 widened): whole-file corruptions and hostile values (NaN,
Infinity, 1e308, negative, zero, wrong types, missing keys, duplicate keys, huge arrays, deep
nesting, BOM/UTF-16, whole numbers of 400 and 5000 digits) in every JSON file a command reads,
hostile images (truncated, empty, forged sizes, wrong content for the suffix, wrong dtype or
channels, NaN/inf depth), hostile numbers for every command's options, permissions (run through
``setpriv`` without root's override of permission bits), long paths, names with newlines or bytes
that are not UTF-8. The last line counts the verdicts (clean, ok, VAGUE, MISHANDLED).

Outputs are only ever written under /tmp/hp/runs: device outputs are private nodes made there,
never /dev/null (an old version replaced the system's /dev/null with a file when run as root).
"""
import json, os, re, shutil, subprocess, sys, hashlib, stat, tempfile
from pathlib import Path
sys.path.insert(0, str(Path(__file__).resolve().parent))
SRC = sys.argv[1]
only = sys.argv[2:] 
os.environ["PYTHONPATH"] = SRC
sys.path.insert(0, SRC)
from test_hostile import _write_inputs, _manifest, W, H
import numpy as np, cv2, tifffile

PY = sys.executable
#: the probe's own folder (fixtures and one fresh folder per case); HP_ROOT to run two probes at once
ROOT = os.environ.get("HP_ROOT", "/tmp/hp")


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
    subprocess.run([PY, "-c", code.replace("/tmp/hp", ROOT)], check=True, env=dict(os.environ, PYTHONPATH=SRC))
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
        shutil.copy(Path(ROOT, "fit") / f, root / f)
    shutil.copytree(f"{ROOT}/fit/recordings", root / "recordings")
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
    s = Path(ROOT, "session"); shutil.copytree(s, r / "s"); os.symlink("L", r / "L")
    return ["calibrate", str(r / "s"), "--out", str(r / "L"), "--report", str(r / "rep.json"), "--quiet"], r / "L"
@case()
def cal_out_is_session_json(r):
    s = Path(ROOT, "session"); shutil.copytree(s, r / "s")
    return ["calibrate", str(r / "s"), "--out", str(r / "s" / "session.json"), "--report", str(r / "rep.json"), "--quiet", "--overwrite"], "session.json"
@case()
def cal_out_fifo(r):
    s = Path(ROOT, "session"); shutil.copytree(s, r / "s"); os.mkfifo(r / "o.json")
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
    s = Path(ROOT, "session"); shutil.copytree(s, r / "s"); os.symlink("L.json", r / "L.json")
    return ["calibrate", str(r / "s"), "--out", str(r / "o.json"), "--report", str(r / "L.json"), "--quiet", "--overwrite"], r / "L.json"
@case()
def own_cal_report_fifo(r):
    s = Path(ROOT, "session"); shutil.copytree(s, r / "s"); os.mkfifo(r / "R.json")
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


# ================================================================== round 4 (issue 22, widened)
# New classes, generated: hostile values inside every JSON file a command reads, whole-file
# corruptions of those files, hostile image files, hostile numbers on the command line,
# permissions (run without root's override of permission bits), long and multi-line paths.
def _edit(path, fn):
    d = json.loads(Path(path).read_text()); fn(d); Path(path).write_text(json.dumps(d))

def _setkey(d, keypath, value):
    """``d`` with ``keypath`` ("cameras.1.K", "*" = delete the key) set to ``value``."""
    parts = keypath.split(".")
    for k in parts[:-1]:
        d = d[int(k)] if isinstance(d, list) else d[k]
    last = parts[-1]
    if value is _DELETE:
        del d[int(last) if isinstance(d, list) else last]
    elif isinstance(d, list):
        d[int(last)] = value
    else:
        d[last] = value
_DELETE = object()

def _cal(r, *extra):
    if not (r / "s").exists():
        shutil.copytree(f"{ROOT}/session", r / "s")
    return ["calibrate", str(r / "s"), "--out", str(r / "o.json"), "--report", str(r / "rep.json"), "--quiet", *extra]

def _intrinsics_rig(r):
    """A one-camera rig file for calibrate --intrinsics ir=FILE (the session's ir camera, 320x240)."""
    d = {"format": "plantreg.rig", "version": 1, "cameras": [{"name": "ir", "modality": "infrared", "width": 320,
         "height": 240, "K": [[300, 0, 159.5], [0, 300, 119.5], [0, 0, 1]], "dist": [0, 0, 0, 0, 0]}]}
    (r / "intr.json").write_text(json.dumps(d)); return r / "intr.json"

# -- the JSON files and how a case reaches each: name -> (make(r) -> (argv, file))
def _j_rig(r):
    rig, rec = mkrec(r); return reg(rig, rec, r / "out"), rig
def _j_manifest(r):
    rig, rec = mkrec(r); return reg(rig, rec, r / "out"), rec / "recording.json"
def _j_session(r):
    a = _cal(r); return a, r / "s" / "session.json"
def _j_landmarks(r):
    rig, rec = mkfit(r); return fit(rig, r / "landmarks.json", r / "o.json"), r / "landmarks.json"
def _j_start(r):
    rig, rec = mkfit(r); return fit(rig, r / "landmarks.json", r / "o.json"), rig
def _j_intrinsics(r):
    f = _intrinsics_rig(r); return _cal(r, "--intrinsics", f"ir={f}"), f
JSON_FILES = {"rig": _j_rig, "manifest": _j_manifest, "session": _j_session, "landmarks": _j_landmarks,
              "startrig": _j_start, "intrinsics": _j_intrinsics}

# -- whole-file corruptions: name -> (bytes from the original, expect)
def _dup_first_key(b):
    d = json.loads(b); k = next(iter(d)); dup = json.dumps({k: "duplicate"})[1:-1]
    return ("{" + dup + ", " + b.decode()[1:]).encode()  # the key twice: json keeps the last silently
FILE_CORRUPTIONS = {
    "empty": (lambda b: b"", "refuse"),
    "whitespace": (lambda b: b"  \n\t\n", "refuse"),
    "text": (lambda b: b"this is not json\n", "refuse"),
    "binary": (lambda b: bytes(range(256)) * 4, "refuse"),
    "truncated": (lambda b: b[: len(b) // 2], "refuse"),
    "top_list": (lambda b: b"[" + b + b"]", "refuse"),
    "top_null": (lambda b: b"null", "refuse"),
    "top_nan": (lambda b: b"NaN", "refuse"),
    "deep_lists": (lambda b: b"[" * 200000 + b"]" * 200000, "refuse"),
    "deep_objects": (lambda b: b'{"a":' * 100000 + b"1" + b"}" * 100000, "refuse"),
    "dup_key_last_wins": (_dup_first_key, "refuse"),
    "utf8_bom": (lambda b: b"\xef\xbb\xbf" + b, "ok"),
    "utf16_bom": (lambda b: b.decode().encode("utf-16"), "ok"),
    "latin1_bytes": (lambda b: b[:-1] + b', "x\xe9": 1}', "refuse"),
    "trailing_garbage": (lambda b: b + b"\n}}garbage", "refuse"),
}
for fname, make in JSON_FILES.items():
    for cname, (mut, exp) in FILE_CORRUPTIONS.items():
        def f(r, make=make, mut=mut, exp=exp):
            argv, file = make(r); file.write_bytes(mut(file.read_bytes()))
            return argv, (None if exp == "ok" else file.name)
        f.__name__ = f"json_{fname}_{cname}"; case(exp)(f)

# -- hostile values at key paths: (file, keypath, value, culprit words)
NAN, INF = float("nan"), float("inf")
VALUES = [
    # rig.json of register
    *[("rig", "cameras.0.width", v, "width") for v in (NAN, INF, 1e308, -1, 0, 2.5, "32", [32], None, True)],
    *[("rig", "cameras.1.K", v, "K") for v in ("K", [[1]], [[NAN, 0, 16], [0, 30, 12], [0, 0, 1]],
                                                 [[1e308, 0, 16], [0, 1e308, 12], [0, 0, 1]], {"fx": 30}, None)],
    *[("rig", "cameras.1.t", v, "t") for v in ([NAN, 0, 0], [1e308, 0, 0], [0, 0], "0,0,0", [[0], [0], [0]])],
    *[("rig", "cameras.1.R", v, "R") for v in ([[2, 0, 0], [0, 2, 0], [0, 0, 2]], [[NAN] * 3] * 3, [1, 0, 0])],
    *[("rig", "cameras.1.dist", v, "dist") for v in ([NAN] * 5, [1e308] * 5, [0.1] * 7, "none")],
    *[("rig", "depth.scale", v, "scale") for v in (NAN, INF, 0, -0.001, 1e308, "0.001", None)],
    *[("rig", "roi.min", v, "roi") for v in ([NAN, 0, 0], [0, 0], "low", [1e308, 0, 0])],
    ("rig", "cameras", {}, "cameras"), ("rig", "cameras", [], "cameras"), ("rig", "cameras", _DELETE, "cameras"),
    ("rig", "cameras.1", "thermal", "cameras[1]"), ("rig", "cameras.1.name", _DELETE, "name"),
    ("rig", "cameras.1.modality", 5, "modality"), ("rig", "depth", [], "depth"), ("rig", "depth.camera", 0, "camera"),
    ("rig", "version", NAN, "version"), ("rig", "version", 1e308, "version"), ("rig", "cameras.0.height", 1e308, "height"),
    # recording.json of register
    *[("manifest", "depth_scale", v, "depth_scale") for v in (NAN, INF, 0, -1, "0.001", 1e308, [0.001])],
    ("manifest", "images", [], "images"), ("manifest", "images.thermal", 5, "thermal"),
    ("manifest", "images.thermal", None, "thermal"), ("manifest", "images.thermal", ["thermal.tif"], "thermal"),
    ("manifest", "depth", ["depth.png"], "depth"), ("manifest", "depth", 7, "depth"),
    ("manifest", "images.nosuchcam", "thermal.tif", "nosuchcam"), ("manifest", "images.thermal", "/etc/passwd", ("passwd", "image type")),
    ("manifest", "images.thermal", "rgb.png", ("rgb.png", "thermal")), ("manifest", "depth", "ir.npy", ("ir.npy", "depth")),
    # session.json of calibrate
    *[("session", "board.columns", v, "columns") for v in (NAN, 0, -9, "9", 1e308, 2.5)],
    ("session", "board.columns", 1, "inner corners"),
    *[("session", "board.square_size", v, "square") for v in (NAN, INF, 0, -0.04, 1e308, "0.04")],
    ("session", "board.type", "hexagon", "type"), ("session", "board", [], "board"), ("session", "board", _DELETE, "board"),
    ("session", "cameras", [], "cameras"), ("session", "cameras", {}, "cameras"), ("session", "cameras.ir", [], "ir"),
    ("session", "depth.scale", NAN, "scale"), ("session", "depth.scale", 1e308, "scale"), ("session", "depth.camera", "x", "camera"),
    ("session", "review", [], "review"), ("session", "review.excluded", "pose_01:ir", "excluded"),
    # landmarks.json of fit-rig
    *[("landmarks", "recordings.recordings/plant51.points.0.depth_uv", v, "depth_uv")
      for v in ([NAN, 1], [INF, 1], [1e308, 1], [-5, -5], "339,377", [1], None, [1, 2, 3])],
    *[("landmarks", "recordings.recordings/plant51.points.0.cameras.rgb", v, "rgb") for v in ([NAN, 1], [1e308, 1e308], {"u": 1})],
    ("landmarks", "recordings", [], "recordings"), ("landmarks", "recordings", _DELETE, "recordings"),
    ("landmarks", "recordings.recordings/plant51.points", {}, "points"), ("landmarks", "version", NAN, "version"),
    ("landmarks", "version", 1e308, "version"), ("landmarks", "format", 5, "format"),
    ("landmarks", "recordings.recordings/plant51.points.0.cameras", [], "cameras"),
    ("landmarks", "recordings.recordings/plant51.points.0.cameras.nosuchcam", [5, 5], "nosuchcam"),
    # start rig of fit-rig and the --intrinsics rig of calibrate
    ("startrig", "cameras.0.K", [[NAN, 0, 1], [0, 1, 1], [0, 0, 1]], "K"), ("startrig", "cameras.0.width", 1e308, "width"),
    ("startrig", "depth", _DELETE, "depth"), ("startrig", "cameras.1.t", [INF, 0, 0], "t"),
    ("intrinsics", "cameras.0.K", [[NAN, 0, 1], [0, 1, 1], [0, 0, 1]], "K"), ("intrinsics", "cameras.0.width", 640, "640"),
    ("intrinsics", "cameras.0.name", "rgb", None),  # its only camera: documented, valid
    ("intrinsics", "cameras.0.dist", [1e308] * 5, "dist"),
    ("intrinsics", "cameras", [], "cameras"),
]
for i, (fname, keypath, value, word) in enumerate(VALUES):
    def f(r, fname=fname, keypath=keypath, value=value, word=word):
        argv, file = JSON_FILES[fname](r); _edit(file, lambda d: _setkey(d, keypath, value))
        if word is None:  # a valid value
            return argv, None
        return argv, (word if isinstance(word, tuple) else (file.name, word))  # a tuple: the file named is another
    tag = re.sub(r"[^A-Za-z0-9]+", "_", f"{keypath}_{'del' if value is _DELETE else json.dumps(value)[:12]}")
    f.__name__ = f"val_{fname}_{tag}_{i}"; case("ok" if word is None else "refuse")(f)
# whole numbers beyond a float (Python parses them exactly, then float() overflows) and beyond
# Python's 4300-digit parsing limit, in a key each file's reader uses
BIG_KEYS = {"rig": "cameras.0.width", "manifest": "depth_scale", "session": "board.columns",
            "landmarks": "version", "startrig": "cameras.0.height", "intrinsics": "cameras.0.width"}
for fname, keypath in BIG_KEYS.items():
    for digits in (400, 5000):
        def f(r, fname=fname, keypath=keypath, digits=digits):
            argv, file = JSON_FILES[fname](r)
            _edit(file, lambda d: _setkey(d, keypath, 123456789))
            file.write_text(file.read_text().replace("123456789", "1" + "0" * (digits - 1), 1))
            return argv, (file.name, str(digits))
        f.__name__ = f"bigint_{fname}_{digits}"; case()(f)
# a rig file list of a million numbers where a few are expected (parsed, then refused by key)
@case()
def val_rig_huge_dist(r):
    argv, file = _j_rig(r); _edit(file, lambda d: _setkey(d, "cameras.1.dist", [0.0] * 1_000_000)); return argv, ("rig.json", "dist")
@case("ok")
def val_rig_huge_unused_array(r):
    argv, file = _j_rig(r); _edit(file, lambda d: _setkey(d, "notes", list(range(500_000)))); return argv, None
@case()
def val_manifest_many_cameras(r):
    argv, file = _j_manifest(r); _edit(file, lambda d: d["images"].update({f"c{i}": "thermal.tif" for i in range(5000)}))
    return argv, ("recording.json", "c0")
@case()
def val_landmarks_too_many_points(r):
    argv, file = _j_landmarks(r)
    _edit(file, lambda d: [v.update(points=v["points"] * 500) for v in d["recordings"].values()])
    return argv, ("landmarks.json", "10000")
@case()
def json_rig_oversize(r):
    argv, file = _j_rig(r); file.write_bytes(b'{"cameras": [' + b"0," * (33 << 20) + b'0]}'); return argv, "rig.json"

# -- hostile image files in a recording (register) and a calibration session (calibrate)
def _png_forged_size(path, w, h, bitdepth=8, ctype=0, plte=False):
    import struct, zlib
    def chunk(k, d): return struct.pack(">I", len(d)) + k + d + struct.pack(">I", zlib.crc32(k + d) & 0xFFFFFFFF)
    body = b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, bitdepth, ctype, 0, 0, 0))
    if plte: body += chunk(b"PLTE", bytes(range(48)))
    body += chunk(b"IDAT", zlib.compress(b"\x00" * 64)) + chunk(b"IEND", b"")
    Path(path).write_bytes(body)
def _tiff_forged_size(path, w, h):
    tifffile.imwrite(path, np.zeros((4, 4), np.uint16))
    b = bytearray(Path(path).read_bytes())
    with tifffile.TiffFile(path) as t:
        tags = t.pages[0].tags
        for name, val in (("ImageWidth", w), ("ImageLength", h)):
            tg = tags[name]; off = tg.valueoffset; size = 2 if tg.dtype == 3 else 4
            b[off:off + size] = val.to_bytes(size, "little")
    Path(path).write_bytes(bytes(b))
IMAGE_CASES = {
    # name: (camera file, writer(path), expect, culprit word)
    "depth_zero_bytes": ("depth.png", lambda p: p.write_bytes(b""), "refuse", "empty"),
    "depth_truncated": ("depth.png", lambda p: p.write_bytes(p.read_bytes()[:60]), "refuse", "truncated"),
    "depth_forged_100000": ("depth.png", lambda p: _png_forged_size(p, 100000, 100000, 16), "refuse", "depth.png"),
    "depth_one_pixel": ("depth.png", lambda p: cv2.imwrite(str(p), np.full((1, 1), 1000, np.uint16)), "refuse", "1x1"),
    "depth_all_zero": ("depth.png", lambda p: cv2.imwrite(str(p), np.zeros((H, W), np.uint16)), "refuse", "depth"),
    "depth_rgb": ("depth.png", lambda p: cv2.imwrite(str(p), np.full((H, W, 3), 100, np.uint8)), "refuse", "channel"),
    "depth_rgba": ("depth.png", lambda p: cv2.imwrite(str(p), np.full((H, W, 4), 100, np.uint8)), "refuse", "channel"),
    "depth_is_tiff_named_png": ("depth.png", lambda p: tifffile.imwrite(p, np.full((H, W), 1000, np.uint16)), "refuse", "PNG"),
    "depth_palette_png": ("depth.png", lambda p: _png_forged_size(p, W, H, 8, 3, plte=True), "refuse", "depth.png"),
    "thermal_zero_bytes": ("thermal.tif", lambda p: p.write_bytes(b""), "refuse", "empty"),
    "thermal_truncated": ("thermal.tif", lambda p: p.write_bytes(p.read_bytes()[:-200]), "refuse", "thermal.tif"),
    "thermal_forged_100000": ("thermal.tif", lambda p: _tiff_forged_size(p, 100000, 100000), "refuse", "thermal.tif"),
    "thermal_png_named_tif": ("thermal.tif", lambda p: p.write_bytes(cv2.imencode(".png", np.zeros((24, 32), np.uint8))[1].tobytes()), "refuse", "thermal.tif"),
    "thermal_one_pixel": ("thermal.tif", lambda p: tifffile.imwrite(p, np.ones((1, 1), np.float32)), "refuse", "1x1"),
    "thermal_stack_pages": ("thermal.tif", lambda p: tifffile.imwrite(p, np.ones((5, 24, 32), np.float32)), "refuse", "thermal.tif"),
    "thermal_complex": ("thermal.tif", lambda p: tifffile.imwrite(p, np.ones((24, 32), np.complex64)), "refuse", "complex"),
    "thermal_text": ("thermal.tif", lambda p: p.write_text("II*\x00 not really"), "refuse", "thermal.tif"),
    "thermal_all_nan": ("thermal.tif", lambda p: tifffile.imwrite(p, np.full((24, 32), np.nan, np.float32)), "ok", None),
    "thermal_inf": ("thermal.tif", lambda p: tifffile.imwrite(p, np.full((24, 32), np.inf, np.float32)), "ok", None),
    "thermal_float64": ("thermal.tif", lambda p: tifffile.imwrite(p, np.full((24, 32), 20.5, np.float64)), "ok", None),
    "thermal_rgba": ("thermal.tif", lambda p: tifffile.imwrite(p, np.full((24, 32, 4), 7, np.uint8)), "ok", None),
    "rgb_forged_100000": ("rgb.png", lambda p: _png_forged_size(p, 100000, 100000, 8, 2), "refuse", "rgb.png"),
    # PNG and JPEG are told apart by their signature, whatever the suffix (docs/errors.md): read as what it is
    "rgb_jpeg_named_png": ("rgb.png", lambda p: p.write_bytes(cv2.imencode(".jpg", np.zeros((60, 80, 3), np.uint8))[1].tobytes()), "ok", None),
    "rgb_16bit": ("rgb.png", lambda p: cv2.imwrite(str(p), np.full((60, 80, 3), 4000, np.uint16)), "ok", None),
    "rgb_gray": ("rgb.png", lambda p: cv2.imwrite(str(p), np.full((60, 80), 7, np.uint8)), "ok", None),
    "rgb_crc_broken": ("rgb.png", lambda p: p.write_bytes(p.read_bytes()[:40] + b"\x00" + p.read_bytes()[41:]), "refuse", "rgb.png"),
    "ir_npy_object": ("ir.npy", lambda p: np.save(p, np.array([[object()]]), allow_pickle=True), "refuse", "ir.npy"),
    "ir_npy_0d": ("ir.npy", lambda p: np.save(p, np.float32(3)), "refuse", "ir.npy"),
    "ir_npy_4d": ("ir.npy", lambda p: np.save(p, np.ones((H, W, 2, 2), np.uint16)), "refuse", "ir.npy"),
    "ir_npy_bool": ("ir.npy", lambda p: np.save(p, np.ones((H, W), bool)), "ok", None),
}
for nm, (fn, writer, exp, word) in IMAGE_CASES.items():
    def f(r, fn=fn, writer=writer, exp=exp, word=word):
        rig, rec = mkrec(r); writer(rec / fn); return reg(rig, rec, r / "out"), (None if exp == "ok" else (fn, word))
    f.__name__ = f"img_{nm}"; case(exp)(f)
# float depth maps: NaN/inf where nothing was measured is how float depth is written; all-NaN is empty
for nm, arr, exp in (("depth_float_nan_holes", "holes", "ok"), ("depth_float_all_nan", "nan", "refuse"),
                     ("depth_float_all_inf", "inf", "refuse"), ("depth_float_negative", "neg", "refuse"),
                     ("depth_float_huge", "huge", "refuse")):
    def f(r, arr=arr, exp=exp):
        rig, rec = mkrec(r)
        d = np.full((H, W), 1.0, np.float32)
        if arr == "holes": d[::3] = np.nan; d[1::7] = np.inf
        elif arr == "nan": d[:] = np.nan
        elif arr == "inf": d[:] = np.inf
        elif arr == "neg": d[:] = -1.0
        elif arr == "huge": d[:] = 3e38
        tifffile.imwrite(rec / "depth.tif", d); _manifest(rec, depth="depth.tif")
        _edit(rec / "recording.json", lambda m: m.update(depth_scale=1.0))
        return reg(rig, rec, r / "out"), (None if exp == "ok" else ("depth.tif", "depth"))
    f.__name__ = f"img_{nm}"; case(exp)(f)
for nm, writer in (("zero_bytes", lambda p: p.write_bytes(b"")), ("truncated", lambda p: p.write_bytes(p.read_bytes()[:100])),
                   ("forged_size", lambda p: _png_forged_size(p, 100000, 100000)), ("text", lambda p: p.write_text("hello"))):
    def f(r, writer=writer):
        a = _cal(r); img = sorted((r / "s" / "pose_01").glob("ir.*"))[0]; writer(img); return a, img.name
    f.__name__ = f"img_session_{nm}"; case()(f)

def _swap(rig_rec, out):
    """(rig, rec), out -> (rig, out, rec): bat()'s order."""
    return rig_rec[0], out, rig_rec[1]


def _option_cases(prefix, make, table):
    """Cases ``PREFIX_NAME`` for (NAME, extra command-line words, culprit word): ``make(r, extra)`` -> argv."""
    for nm, extra, word in table:
        def f(r, extra=extra, word=word):
            return make(r, extra), word
        f.__name__ = f"{prefix}_{nm}"; case()(f)
# -- hostile numbers on the command line
def _rig_create(r, *cams, extra=()):
    return ["rig", "create", str(r / "new.json"), "--depth-camera", "ir",
            *[x for c in (cams or ("ir=infrared,640x576,f=504,rot=0",)) for x in ("--camera", c)], *extra]
RC_OK = "rgb=rgb,1280x720,hfov=90,rot=0,at=0.03,0,0"
for nm, spec, word in (("size_zero", "rgb=rgb,0x0,hfov=90,rot=0", "0x0"), ("size_negative", "rgb=rgb,-5x10,hfov=90,rot=0", "-5x10"),
                       ("size_huge", "rgb=rgb,100000x100000,hfov=90,rot=0", "100000"), ("size_words", "rgb=rgb,axb,hfov=90,rot=0", "axb"),
                       ("hfov_zero", "rgb=rgb,1280x720,hfov=0,rot=0", "hfov"), ("hfov_180", "rgb=rgb,1280x720,hfov=180,rot=0", "hfov"),
                       ("hfov_nan", "rgb=rgb,1280x720,hfov=nan,rot=0", "hfov"), ("hfov_neg", "rgb=rgb,1280x720,hfov=-10,rot=0", "hfov"),
                       ("hfov_inf", "rgb=rgb,1280x720,hfov=inf,rot=0", "hfov"), ("hfov_1e308", "rgb=rgb,1280x720,hfov=1e308,rot=0", "hfov"),
                       ("vfov_nan", "rgb=rgb,1280x720,hfov=90,vfov=nan,rot=0", "vfov"), ("f_neg", "rgb=rgb,1280x720,f=-5,rot=0", "f"),
                       ("f_zero", "rgb=rgb,1280x720,f=0,rot=0", "f"), ("f_nan", "rgb=rgb,1280x720,f=nan,rot=0", "f"),
                       ("f_1e308", "rgb=rgb,1280x720,f=1e308,rot=0", "f"), ("fy_neg", "rgb=rgb,1280x720,f=500,fy=-1,rot=0", "fy"),
                       ("rot_45", "rgb=rgb,1280x720,hfov=90,rot=45", "rot"), ("rot_nan", "rgb=rgb,1280x720,hfov=90,rot=nan", "rot"),
                       ("at_nan", "rgb=rgb,1280x720,hfov=90,rot=0,at=nan,0,0", "at"), ("at_1e308", "rgb=rgb,1280x720,hfov=90,rot=0,at=1e308,0,0", "at"),
                       ("at_two", "rgb=rgb,1280x720,hfov=90,rot=0,at=1,2", "at"), ("no_lens", "rgb=rgb,1280x720,rot=0", "rgb"),
                       ("bad_modality", "rgb=sonar,1280x720,hfov=90,rot=0", "sonar"), ("name_slash", "a/b=rgb,1280x720,hfov=90,rot=0", "a/b"),
                       ("name_newline", "a\nb=rgb,1280x720,hfov=90,rot=0", "U+000A"), ("kinect_devzero", "rgb=rgb,640x576,kinect=/dev/zero,rot=0", "/dev/zero"),
                       ("kinect_missing", "rgb=rgb,640x576,kinect=/nonexistent/cal.json,rot=0", "cal.json")):
    def f(r, spec=spec, word=word):
        return _rig_create(r, "ir=infrared,640x576,f=504,rot=0", spec), word
    f.__name__ = f"num_rigcreate_{nm}"; case()(f)
@case()
def num_rigcreate_kinect_notjson(r):
    (r / "k.json").write_text("garbage"); return _rig_create(r, "ir=infrared,640x576,f=504,rot=0", f"rgb=rgb,640x576,kinect={r / 'k.json'},rot=0"), "k.json"
@case()
def num_rigcreate_kinect_nan(r):
    (r / "k.json").write_text('{"CalibrationInformation": {"Cameras": [{"Intrinsics": {"ModelParameters": [NaN, NaN]}}]}}')
    return _rig_create(r, "ir=infrared,640x576,f=504,rot=0", f"rgb=rgb,640x576,kinect={r / 'k.json'},rot=0"), "k.json"
@case()
def num_rigcreate_dup_names(r):
    return _rig_create(r, "ir=infrared,640x576,f=504,rot=0", RC_OK, RC_OK), "rgb"
@case()
def num_rigcreate_depth_cam_missing(r):
    return ["rig", "create", str(r / "new.json"), "--depth-camera", "nosuch", "--camera", RC_OK], "nosuch"
_option_cases("num_rigcreate", lambda r, extra: _rig_create(r, "ir=infrared,640x576,f=504,rot=0", RC_OK, extra=extra), (("scale_nan", ("--depth-scale", "nan"), "scale"), ("scale_zero", ("--depth-scale", "0"), "scale"),
                        ("scale_neg", ("--depth-scale", "-1"), "scale"), ("scale_inf", ("--depth-scale", "inf"), "scale"),
                        ("roi_nan", ("--roi", "nan,0,0,1,1,1"), "roi"), ("roi_inf", ("--roi", "0,0,0,inf,1,1"), "roi"),
                        ("roi_min_gt_max", ("--roi", "1,1,1,0,0,0"), "roi"), ("roi_five", ("--roi", "0,0,0,1,1"), "roi"),
                        ("roi_1e308", ("--roi", "-1e308,0,0,1e308,1,1"), "roi")))
@case("ok")
def num_rigcreate_valid(r):
    return _rig_create(r, "ir=infrared,640x576,f=504,rot=0", RC_OK, extra=("--roi=-0.5,-0.5,0.2,0.5,0.5,1.2",)), None
_option_cases("num_cal", lambda r, extra: _cal(r, *extra), (("max_rms_neg", ("--max-rms", "-1"), "--max-rms"), ("max_rms_zero", ("--max-rms", "0"), "--max-rms"),
                        ("max_rms_nan", ("--max-rms", "nan"), "--max-rms"), ("max_rms_inf", ("--max-rms", "inf"), "--max-rms"),
                        ("roi_nan", ("--roi", "nan", "0", "0", "1", "1", "1"), "--roi"), ("roi_min_gt_max", ("--roi", "1", "1", "1", "0", "0", "0"), "--roi"),
                        ("roi_1e308", ("--roi", "-1e308", "-1", "0", "1e308", "1", "1"), "--roi"),
                        ("exclude_garbage", ("--exclude", "nocolon"), "nocolon"), ("exclude_unknown", ("--exclude", "pose_99:ir"), "pose_99"),
                        ("intrinsics_nosep", ("--intrinsics", "ir"), "--intrinsics"), ("intrinsics_unknown_cam", ("--intrinsics", "zz=x.json"), "zz"),
                        ("intrinsics_missing_file", ("--intrinsics", "ir=/nonexistent.json"), "nonexistent.json"),
                        ("intrinsics_devzero", ("--intrinsics", "ir=/dev/zero"), "/dev/zero")))
_option_cases("num_fit", lambda r, extra: fit(mkfit(r)[0], r / "landmarks.json", r / "o.json", *extra), (("max_median_nan", ("--max-median", "nan"), "--max-median"), ("max_median_neg", ("--max-median", "-1"), "--max-median"),
                        ("max_median_zero", ("--max-median", "0"), "--max-median"), ("max_median_inf", ("--max-median", "inf"), "--max-median"),
                        ("worst_neg", ("--worst", "-1"), "--worst"), ("worst_huge", ("--worst", "99999999999999999999999"), "--worst"),
                        ("prior_nan", ("--prior", "rotation=nan"), "rotation"), ("prior_neg", ("--prior", "focal=-1"), "focal"),
                        ("prior_zero", ("--prior", "position=0"), "position"), ("prior_inf", ("--prior", "click=inf"), "click"),
                        ("prior_1e308", ("--prior", "robust=1e308"), "robust"), ("prior_unknown", ("--prior", "colour=1"), "colour"),
                        ("prior_novalue", ("--prior", "rotation"), "rotation"), ("prior_twoeq", ("--prior", "rotation=5=6"), "rotation"),
                        ("free_unknown", ("--free", "zoom"), "zoom"), ("free_unknown_cam", ("--free", "nosuch:focal"), "nosuch"),
                        ("fit_unknown_cam", ("--fit", "nosuch"), "nosuch"), ("fit_empty", ("--fit", ","), "--fit")))
_option_cases("num_reg", lambda r, extra: reg(*mkrec(r), r / "out", *extra), (("edge_nan", ("--edge-angle", "nan"), "--edge-angle"), ("edge_neg", ("--edge-angle", "-5"), "edge"),
                        ("edge_1e308", ("--edge-angle", "1e308"), "edge"), ("edge_zero", ("--edge-angle", "0"), "edge"),
                        ("edge_90", ("--edge-angle", "90"), "edge"), ("jump_neg", ("--flying-jump", "-1"), "flying"),
                        ("jump_zero", ("--flying-jump", "0"), "flying"), ("jump_inf", ("--flying-jump", "inf"), "--flying-jump"),
                        ("denoise_neg", ("--denoise-size", "-1"), "denoise"), ("denoise_even", ("--denoise-size", "4"), "denoise"),
                        ("denoise_huge", ("--denoise-size", "1000000001"), "denoise"), ("mixed_neg", ("--mixed-radius", "-1"), "mixed"),
                        ("mixed_1e308", ("--mixed-radius", "1e308"), "mixed"), ("outputs_bogus", ("--outputs", "bogus"), "bogus"),
                        ("outputs_empty", ("--outputs", ""), "--outputs"), ("outputs_commas", ("--outputs", ",,"), "--outputs")))
@case()
def num_reg_target_empty(r):
    rig, rec = mkrec(r); a = reg(rig, rec, r / "out"); a[a.index("--target") + 1] = ""; return a, "target"
@case()
def num_reg_target_unknown(r):
    rig, rec = mkrec(r); a = reg(rig, rec, r / "out"); a[a.index("--target") + 1] = "nosuch"; return a, "nosuch"
_option_cases("num_batch", lambda r, extra: bat(*_swap(mkrec(r), r / "out"), *extra), (("workers_zero", ("--workers", "0"), "--workers"), ("workers_neg", ("--workers", "-3"), "--workers"),
                        ("workers_huge", ("--workers", "100000000000000000000"), "--workers"), ("workers_nan", ("--workers", "nan"), "--workers"),
                        ("edge_nan", ("--edge-angle", "nan"), "--edge-angle"), ("scheduler_garbage", ("--scheduler", "not an address"), "--scheduler")))
_option_cases("num_demo", lambda r, extra: ["demo", str(r / "d"), "--quiet", *extra], (("seed_neg", ("--seed", "-1"), "--seed"), ("seed_huge", ("--seed", str(2 ** 64)), "--seed"),
                        ("seed_nan", ("--seed", "nan"), "--seed"), ("size_bogus", ("--size", "huge"), "--size")))
_option_cases("num_rc", lambda r, extra: _imgs(r) or rc(r / "rec", "--depth", str(r / "depth.png"), *extra), (("depth_scale_nan", ("--depth-scale", "nan"), "--depth-scale"), ("depth_scale_neg", ("--depth-scale", "-1"), "--depth-scale"),
                        ("depth_scale_inf", ("--depth-scale", "inf"), "--depth-scale"), ("depth_scale_1e308", ("--depth-scale", "1e308"), "--depth-scale")))

# -- permissions: run without root's override of permission bits (setpriv drops CAP_DAC_*)
NOCAP = "__NOCAP__"
for nm, target in (("rig", "rig"), ("manifest", "manifest"), ("image", "thermal"), ("depth", "depth"), ("rec_folder", "recfolder")):
    def f(r, target=target):
        rig, rec = mkrec(r)
        p = {"rig": rig, "manifest": rec / "recording.json", "thermal": rec / "thermal.tif", "depth": rec / "depth.png",
             "recfolder": rec}[target]
        os.chmod(p, 0o000)
        return reg(rig, rec, r / "out") + [NOCAP], p.name
    f.__name__ = f"perm_reg_unreadable_{nm}"; case()(f)
@case()
def perm_reg_out_parent_readonly(r):
    rig, rec = mkrec(r); (r / "ro").mkdir(); os.chmod(r / "ro", 0o555); return reg(rig, rec, r / "ro" / "o") + [NOCAP], "ro"
@case()
def perm_reg_overwrite_readonly_out(r):
    rig, rec = mkrec(r); (r / "out").mkdir(); (r / "out" / "old.txt").write_text("x"); os.chmod(r / "out", 0o555)
    return reg(rig, rec, r / "out", "--overwrite") + [NOCAP], "out"
@case()
def perm_fit_unreadable_landmarks(r):
    rig, rec = mkfit(r); os.chmod(r / "landmarks.json", 0); return fit(rig, r / "landmarks.json", r / "o.json") + [NOCAP], "landmarks.json"
@case()
def perm_fit_unreadable_depth(r):
    rig, rec = mkfit(r); d = next(rec.glob("depth.*")); os.chmod(d, 0)
    return fit(rig, r / "landmarks.json", r / "o.json") + [NOCAP], d.name
@case()
def perm_fit_out_readonly(r):
    rig, rec = mkfit(r); (r / "ro").mkdir(); os.chmod(r / "ro", 0o555); return fit(rig, r / "landmarks.json", r / "ro" / "o.json") + [NOCAP], "ro"
@case()
def perm_cal_unreadable_image(r):
    a = _cal(r); img = sorted((r / "s" / "pose_02").glob("rgb.*"))[0]; os.chmod(img, 0); return a + [NOCAP], img.name
@case()
def perm_cal_unreadable_session(r):
    a = _cal(r); os.chmod(r / "s" / "session.json", 0); return a + [NOCAP], "session.json"
@case()
def perm_cal_out_readonly(r):
    a = _cal(r); (r / "ro").mkdir(); os.chmod(r / "ro", 0o555); a[a.index("--out") + 1] = str(r / "ro" / "o.json"); return a + [NOCAP], "ro"
@case()
def perm_rc_unreadable_image(r):
    _imgs(r); os.chmod(r / "ir.png", 0); return rc(r / "rec", "--image", f"ir={r / 'ir.png'}") + [NOCAP], "ir.png"
@case()
def perm_rc_dir_readonly(r):
    _imgs(r); (r / "ro").mkdir(); os.chmod(r / "ro", 0o555); return rc(r / "ro", "--depth", str(r / "depth.png")) + [NOCAP], "ro"
@case()
def perm_batch_out_readonly(r):
    rig, rec = mkrec(r); (r / "ro").mkdir(); os.chmod(r / "ro", 0o555); return bat(rig, r / "ro", rec) + [NOCAP], "ro"
@case()
def perm_batch_unreadable_recording(r):
    rig, rec = mkrec(r); os.chmod(rec / "recording.json", 0); return bat(rig, r / "out", rec) + [NOCAP], "recording.json"
@case()
def perm_demo_readonly(r):
    (r / "ro").mkdir(); os.chmod(r / "ro", 0o555); return ["demo", str(r / "ro" / "d"), "--quiet"] + [NOCAP], "ro"
@case()
def perm_rigcreate_readonly(r):
    (r / "ro").mkdir(); os.chmod(r / "ro", 0o555)
    return ["rig", "create", str(r / "ro" / "n.json"), "--depth-camera", "ir", "--camera", "ir=infrared,640x576,f=504,rot=0"] + [NOCAP], "ro"

# -- long paths and names with newlines
@case()
def long_input_rig_component(r):
    rig, rec = mkrec(r); return reg(r / ("r" * 300 + ".json"), rec, r / "out"), "r" * 30
@case()
def long_input_total_path(r):
    rig, rec = mkrec(r); deep = r / "/".join(["d" * 200] * 25) / "rig.json"; return reg(deep, rec, r / "out"), "d" * 30
@case()
def long_out_total_path(r):
    rig, rec = mkrec(r); deep = r / "/".join(["d" * 200] * 25); return reg(rig, rec, deep), "d" * 30
@case()
def long_manifest_image_name(r):
    rig, rec = mkrec(r); _manifest(rec, thermal="t" * 300 + ".tif"); return reg(rig, rec, r / "out"), "t" * 30
@case()
def long_rc_image_component(r):
    _imgs(r); return rc(r / "rec", "--image", f"ir={r / ('i' * 300 + '.png')}"), "i" * 30
@case()
def long_fit_out_total(r):
    rig, rec = mkfit(r); return fit(rig, r / "landmarks.json", r / "/".join(["d" * 200] * 25) / "o.json"), "d" * 30
@case("ok")
def newline_out_folder(r):
    rig, rec = mkrec(r); return reg(rig, rec, r / "out\nx"), None
@case("ok")
def newline_recording_folder(r):
    rig, rec = mkrec(r); shutil.move(rec, r / "re\nc"); return reg(rig, r / "re\nc", r / "out"), None
@case()
def newline_missing_recording(r):
    rig, rec = mkrec(r); return reg(rig, r / "no\nsuch", r / "out"), "such"
@case()
def newline_missing_image(r):
    rig, rec = mkrec(r); _manifest(rec, thermal="ther\nmal.tif"); return reg(rig, rec, r / "out"), "mal.tif"
@case("ok")
def newline_batch_recording(r):
    rig, rec = mkrec(r); shutil.move(rec, r / "re\nc"); return bat(rig, r / "out", r / "re\nc"), None
@case()
def newline_batch_failing_recording(r):
    rig, rec = mkrec(r); shutil.move(rec, r / "re\nc"); (r / "re\nc" / "thermal.tif").write_bytes(b"")
    return bat(rig, r / "out", r / "re\nc"), "thermal.tif"
@case()
def newline_cal_out(r):
    a = _cal(r, "--max-rms", "0.0000001"); a[a.index("--out") + 1] = str(r / "o\n.json"); return a, "max-rms"
@case()
def newline_rc_missing_depth(r):
    _imgs(r); return rc(r / "rec", "--depth", str(r / "de\npth.png")), "pth.png"


# -- file names that are not UTF-8 (Python holds their bytes as surrogates): read, written, printed
NOT_UTF8 = os.fsdecode(b"re\xffc")
@case("ok")
def bytes_out_folder(r):
    rig, rec = mkrec(r); return reg(rig, rec, r / NOT_UTF8), None
@case("ok")
def bytes_recording_folder(r):
    rig, rec = mkrec(r); shutil.move(rec, r / NOT_UTF8); return reg(rig, r / NOT_UTF8, r / "out"), None
@case("ok")
def bytes_batch(r):
    rig, rec = mkrec(r); shutil.move(rec, r / NOT_UTF8); return bat(rig, r / ("o" + NOT_UTF8), r / NOT_UTF8), None
@case("ok")
def bytes_recording_create(r):
    _imgs(r); os.rename(r / "ir.png", r / (NOT_UTF8 + ".png"))
    return rc(r / NOT_UTF8, "--image", f"ir={r / (NOT_UTF8 + '.png')}"), None
@case()
def bytes_missing_image(r):
    rig, rec = mkrec(r); _manifest(rec, thermal=NOT_UTF8 + ".tif"); return reg(rig, rec, r / "out"), "re"
@case("ok")
def bytes_fit_out(r):
    rig, rec = mkfit(r); return fit(rig, r / "landmarks.json", r / (NOT_UTF8 + ".json")), None


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
    r = Path(tempfile.mkdtemp(prefix="hp_", dir=f"{ROOT}/runs"))
    argv, culprit = f(r)
    cwd = r / "cwd" if (r / "cwd").is_dir() else r
    before = snapshot(r)
    stdout = subprocess.PIPE; pre = None; shell_prefix = None
    if "__CLOSE_STDOUT__" in argv:
        argv.remove("__CLOSE_STDOUT__"); stdout = "close"
    if "__DEVFULL__" in argv:
        argv.remove("__DEVFULL__"); stdout = open("/dev/full", "w")
    nocap = NOCAP in argv
    if nocap:  # as root without CAP_DAC_OVERRIDE/READ_SEARCH: permission bits apply, as for any user
        argv.remove(NOCAP)
    if "__ULIMIT__" in argv:
        argv.remove("__ULIMIT__")
        import resource
        pre = lambda: resource.setrlimit(resource.RLIMIT_AS, (900000 * 1024, 900000 * 1024))
    cmd = [PY, "-m", "plantreg_gui", *argv]
    if nocap:
        cmd = ["setpriv", "--bounding-set=-dac_override,-dac_read_search", *cmd]
    if stdout == "close":
        import shlex
        p = subprocess.run(["bash", "-c", " ".join(map(shlex.quote, cmd)) + " >&-"], stderr=subprocess.PIPE, text=True, errors="surrogateescape", cwd=cwd, timeout=300)
        out = ""
    else:
        p = subprocess.run(cmd, stdout=stdout, stderr=subprocess.PIPE, text=True, errors="surrogateescape", cwd=cwd, timeout=300, preexec_fn=pre)
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
            elif p.returncode == 2 and len(lines) >= 2 and lines[0].startswith("usage:") and ": error: " in lines[-1]:
                lines = lines[-1:]  # argparse's usage + one error line naming the option, exit 2
            if argv[0] == "batch":  # a summary line, then one "failed RECORDING: why" line per recording
                lines = [l for l in lines if not re.match(r"\d+ recording\(s\): ", l)]  # all but the summary
                if any(len(str(w)) > 8 and l.count(str(w)) > 1 for w in need for l in lines if "failed" in l[:9]):
                    lines = lines * 2  # the recording named twice ("failed X: X: ..."): vague
            if len(lines) != 1 or miss or ".part" in err or "XXXX" in err:
                verdict = "VAGUE"
    shutil.rmtree(r, ignore_errors=True)
    if os.path.exists(r):
        subprocess.run(["chmod", "-R", "u+w", str(r)]); shutil.rmtree(r, ignore_errors=True)
    return verdict, p.returncode, (problems, err.strip()[-300:])

def run_cases(cases, run, only, width: int = 32, error_chars: int | None = None) -> None:
    """Run each ``(name, make, expect)`` of ``cases`` whose name contains one of ``only`` (all
    without) through ``run``, print a verdict line each and the totals (both probes' report)."""
    counts = {}
    for name, f, expect in cases:
        if only and not any(o in name for o in only):
            continue
        try:
            v, rc_, info = run(name, f, expect)
        except Exception as e:
            v, rc_, info = "PROBE-ERROR", None, repr(e)[:error_chars]
        counts[v] = counts.get(v, 0) + 1
        print(f"{v:11s} {name:{width}s} rc={rc_} {info if v not in ('clean','ok') else ''}", flush=True)
    print("TOTAL", sum(counts.values()), counts)


if __name__ == "__main__":
    Path(ROOT, "runs").mkdir(parents=True, exist_ok=True)
    _fixtures()
    run_cases(CASES, run_case, only)
