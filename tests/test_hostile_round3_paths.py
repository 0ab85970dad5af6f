"""Hostile inputs, round 3 (issue 22): paths that are not plain, outputs over inputs, camera names
and output names -- by mechanism, for every command that writes.

Every refusal: exit 1, exactly one line on stderr naming the user's path (never a temporary
``.NAME.XXXX.part``), no traceback, and the folder the test built byte for byte as it was (the
inputs unchanged, nothing half-written, no leftovers). The commands run in real subprocesses
(``python -m plantreg_gui``), as a user runs them; every input is generated here.
The promise: docs/errors.md, "Paths, names and outputs".
"""

from __future__ import annotations

import errno
import hashlib
import json
import os
import shutil
import stat
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from test_cli_fit_rig import fit_inputs  # noqa: F401 (fixture: the demo rig, 2 recordings, 24 landmarks)
from test_hostile import _env, _manifest, _write_inputs

from plantreg_gui.core.errors import InputError
from plantreg_gui.core.export import export


# ---------------------------------------------------------------------- helpers
def _snapshot(root: Path) -> dict[str, str]:
    """Every entry under ``root`` (links not followed, FIFOs never opened): content hash of a
    regular file, the type of anything else."""
    out = {}
    for dirpath, dirnames, filenames in os.walk(root):
        for name in dirnames + filenames:
            p = Path(dirpath) / name
            st = os.lstat(p)
            if stat.S_ISREG(st.st_mode):
                out[str(p.relative_to(root))] = hashlib.sha1(p.read_bytes()).hexdigest()
            elif stat.S_ISLNK(st.st_mode):
                out[str(p.relative_to(root))] = "link -> " + os.readlink(p)
            else:
                out[str(p.relative_to(root))] = f"type {stat.S_IFMT(st.st_mode):o}"
    return out


def _run(argv: list[str], cwd: Path, **kw) -> subprocess.CompletedProcess:
    kw = {"stdout": subprocess.PIPE, "stderr": subprocess.PIPE, **kw}
    return subprocess.run([sys.executable, "-m", "plantreg_gui", *map(str, argv)], env=_env(), cwd=cwd,
                          text=True, timeout=300, **kw)


def _refused(r: subprocess.CompletedProcess, culprit, *words: str) -> None:
    err = r.stderr
    assert r.returncode == 1, (r.returncode, err, r.stdout)
    assert "Traceback" not in err and "Exception ignored" not in err, err
    assert len(err.strip().splitlines()) == 1, err
    assert str(culprit) in err, err
    assert ".part" not in err and ".old" not in err, err  # never an internal temporary name
    for w in words:
        assert w in err, err


def _refused_unchanged(root: Path, argv: list[str], culprit, *words: str, cwd: Path | None = None, **kw) -> str:
    """Run, assert the refusal and that nothing under ``root`` changed; the message."""
    before = _snapshot(root)
    r = _run(argv, cwd or root, **kw)
    _refused(r, culprit, *words)
    assert _snapshot(root) == before
    return r.stderr


def _device(path: Path) -> Path:
    """A private character device node like /dev/null (never the system's own: an output that
    replaced it would break the machine). Needs root; elsewhere a FIFO stands in."""
    try:
        os.mknod(path, 0o666 | stat.S_IFCHR, os.makedev(1, 3))
    except PermissionError:
        os.mkfifo(path)
    return path


def _rename_camera(rig: Path, rec: Path, old: str, new: str) -> None:
    d = json.loads(rig.read_text())
    next(c for c in d["cameras"] if c["name"] == old)["name"] = new
    rig.write_text(json.dumps(d))
    m = json.loads((rec / "recording.json").read_text())
    m["images"][new] = m["images"].pop(old)
    (rec / "recording.json").write_text(json.dumps(m))


def _register(rig, rec, out, *extra):
    return ["register", "--rig", rig, "--recording", rec, "--target", "ir", "--out", out, "--quiet", *extra]


# ---------------------------------------------------------------------- 1. outputs never replace an input
@pytest.fixture
def fit_copy(fit_inputs, tmp_path):  # noqa: F811
    root, _ = fit_inputs
    dst = tmp_path / "lab"
    shutil.copytree(root, dst)
    return dst


def _fit(lab: Path, out, *extra):
    return ["fit-rig", "--rig", lab / "start.json", "--landmarks", lab / "landmarks.json", "--out", out, "--quiet",
            *extra]


@pytest.mark.parametrize("which", ["start rig", "manifest", "depth map", "link to the start rig"])
def test_fit_rig_never_writes_over_what_it_reads(fit_copy, which):
    """``--out`` onto the start rig, a landmark recording's manifest or depth map, or a symbolic
    link to the start rig, even with ``--overwrite``: refused before the fit, nothing changed
    (the old code compared --out with --landmarks only: each of these was replaced)."""
    lab = fit_copy
    out = {"start rig": lab / "start.json", "manifest": lab / "recordings/plant51/recording.json",
           "depth map": lab / "recordings/plant51/depth.png", "link to the start rig": lab / "ln.json"}[which]
    if which.startswith("link"):
        os.symlink(lab / "start.json", out)
    _refused_unchanged(lab, _fit(lab, out, "--overwrite"), out, "would replace an input")


@pytest.mark.parametrize("kind", ["fifo", "device", "loop"])
def test_fit_rig_output_that_is_not_a_plain_file(fit_copy, kind):
    lab = fit_copy
    out = lab / "o.json"
    if kind == "fifo":
        os.mkfifo(out)
    elif kind == "device":
        _device(out)
    else:
        os.symlink(out.name, out)
    word = {"fifo": "FIFO", "device": "device" if os.geteuid() == 0 else "FIFO", "loop": "symbolic link loop"}[kind]
    _refused_unchanged(lab, _fit(lab, out, "--overwrite"), out, word)


@pytest.mark.parametrize("kind", ["folder", "fifo", "device"])
def test_fit_rig_landmarks_that_are_not_a_file(fit_copy, kind):
    """A folder, FIFO or device given as --landmarks is named as what it is ("not found" was wrong)."""
    lab = fit_copy
    lm = {"folder": lab / "lm", "fifo": lab / "lm.json", "device": Path("/dev/zero")}[kind]
    if kind == "folder":
        lm.mkdir()
    elif kind == "fifo":
        os.mkfifo(lm)
    argv = ["fit-rig", "--rig", lab / "start.json", "--landmarks", lm, "--out", lab / "o.json", "--quiet"]
    _refused_unchanged(lab, argv, lm, {"folder": "is a folder", "fifo": "FIFO", "device": "device"}[kind])


def test_fit_rig_degenerate_landmarks_name_the_file(fit_copy):
    """Landmarks that cannot determine a pose (all at one spot): the message names the landmarks file."""
    lab = fit_copy
    d = json.loads((lab / "landmarks.json").read_text())
    p0 = d["recordings"]["recordings/plant51"]["points"][0]
    d["recordings"] = {"recordings/plant51": {"points": [p0] * 8}}
    (lab / "landmarks.json").write_text(json.dumps(d))
    _refused_unchanged(lab, _fit(lab, lab / "o.json"), lab / "landmarks.json", "one spot")


def test_register_output_over_an_image_outside_the_recording(tmp_path):
    """A recording may list images outside its folder; --out onto their folder is still an input,
    refused before the registration (no progress line; the old code found it only when writing)."""
    rig, rec = _write_inputs(tmp_path)
    (tmp_path / "shared").mkdir()
    shutil.move(rec / "thermal.tif", tmp_path / "shared" / "thermal.tif")
    _manifest(rec, thermal="../shared/thermal.tif")
    argv = [a for a in _register(rig, rec, tmp_path / "shared", "--overwrite") if a != "--quiet"]
    err = _refused_unchanged(tmp_path, argv, tmp_path / "shared", "would replace an input", "thermal.tif")
    assert "%]" not in err


def test_recording_create_never_replaces_a_special_file(tmp_path):
    """``recording create DIR --overwrite`` where DIR/recording.json is a FIFO or a link loop."""
    rig, rec = _write_inputs(tmp_path)
    for name, make, word in (("a", os.mkfifo, "FIFO"), ("b", lambda p: os.symlink(p.name, p), "symbolic link loop")):
        d = tmp_path / name
        d.mkdir()
        make(d / "recording.json")
        _refused_unchanged(tmp_path, ["recording", "create", d, "--depth", rec / "depth.png", "--overwrite"],
                           d / "recording.json", word)


def test_calibrate_output_that_is_a_fifo_or_a_loop(tmp_path):
    """The old code replaced a FIFO given as calibrate's --out (exit 0) and gave a traceback for a loop."""
    from plantreg_gui.core.calibration.board import Board
    from plantreg_gui.core.calibration.synthetic import write_calibration_session
    from plantreg_gui.core.camera.camera import Camera
    from plantreg_gui.core.camera.rig import Rig
    from test_hostile import _K

    rig = Rig([Camera("ir", "infrared", 320, 240, _K(300, 320, 240)),
               Camera("rgb", "rgb", 320, 240, _K(320, 320, 240), t_cam_rig=[0.05, 0, 0])],
              depth_camera="ir", roi_min=[-1, -1, 0.2], roi_max=[1, 1, 1.5])
    write_calibration_session(rig, tmp_path / "session", n_poses=4, board=Board("chessboard", 9, 6, 0.04))
    os.mkfifo(tmp_path / "fifo.json")
    os.symlink("loop.json", tmp_path / "loop.json")
    for out, word in ((tmp_path / "fifo.json", "FIFO"), (tmp_path / "loop.json", "symbolic link loop")):
        _refused_unchanged(tmp_path, ["calibrate", tmp_path / "session", "--out", out, "--report",
                                      tmp_path / "r.json", "--quiet", "--overwrite"], out, word)
        _refused_unchanged(tmp_path, ["calibrate", tmp_path / "session", "--out", tmp_path / "rig.json", "--report",
                                      out, "--quiet", "--overwrite"], out, word)


# ---------------------------------------------------------------------- 4. paths that are not plain
@pytest.mark.parametrize("which", ["recording", "out", "out --overwrite", "rig"])
def test_register_symlink_loops(tmp_path, which):
    rig, rec = _write_inputs(tmp_path)
    loop = tmp_path / "L"
    os.symlink("L", loop)
    argv = {"recording": _register(rig, loop, tmp_path / "out"), "out": _register(rig, rec, loop),
            "out --overwrite": _register(rig, rec, loop, "--overwrite"), "rig": _register(loop, rec, tmp_path / "out")}
    _refused_unchanged(tmp_path, argv[which], loop, "symbolic link loop")


@pytest.mark.parametrize("key", ["thermal", "depth"])
def test_nul_byte_in_a_recording_path(tmp_path, key):
    """``"the\\u0000rmal.tif"`` in recording.json: one line naming the manifest's entry, before any
    registration (the old code: ValueError: embedded null byte)."""
    rig, rec = _write_inputs(tmp_path)
    _manifest(rec, **{key: {"thermal": "the\u0000rmal.tif", "depth": "dep\u0000th.png"}[key]})
    _refused_unchanged(tmp_path, _register(rig, rec, tmp_path / "out"), "\\0", "NUL", "recording.json")


def test_empty_tiff_says_empty(tmp_path):
    rig, rec = _write_inputs(tmp_path)
    (rec / "thermal.tif").write_bytes(b"")
    err = _refused_unchanged(tmp_path, _register(rig, rec, tmp_path / "out"), rec / "thermal.tif", "empty")
    assert "header=b''" not in err


def test_envi_cube_beside_a_folder_of_its_name_is_read(tmp_path):
    """``hyperspectral.hdr`` + ``hyperspectral.img`` and a sibling folder ``hyperspectral/``: a valid
    cube (the folder was taken as its data file and the cube refused)."""
    import spectral.io.envi as envi

    rig, rec = _write_inputs(tmp_path)
    cube = np.random.default_rng(5).random((24, 32, 5)).astype(np.float32)
    envi.save_image(str(rec / "hyperspectral.hdr"), cube, force=True, interleave="bsq", ext=".img")
    (rec / "hyperspectral").mkdir()
    from plantreg_gui.core.io.imageio import read_image

    assert np.array_equal(read_image(rec / "hyperspectral.hdr"), cube)


def test_out_dot_is_refused_before_the_work(tmp_path):
    """``--out .`` in an empty folder: refused at once (no progress line: nothing was registered),
    as is any output folder holding the current folder."""
    rig, rec = _write_inputs(tmp_path)
    cwd = tmp_path / "here"
    cwd.mkdir()
    before = _snapshot(tmp_path)
    r = _run(["register", "--rig", rig, "--recording", rec, "--target", "ir", "--out", "."], cwd)
    assert "%]" not in r.stderr, r.stderr  # refused before any progress
    _refused(r, ".", "current folder")
    assert _snapshot(tmp_path) == before


def test_closed_and_full_standard_output(tmp_path):
    """``>&-``: refused at once (the old code wrote everything, then AttributeError); ``>/dev/full``:
    one line naming standard output (the old one said only "No space left on device")."""
    rig, rec = _write_inputs(tmp_path)
    r = subprocess.run(f'"{sys.executable}" -m plantreg_gui register --rig "{rig}" --recording "{rec}" --target ir '
                       f'--out "{tmp_path / "out"}" --quiet >&-', shell=True, env=_env(), cwd=tmp_path,
                       stderr=subprocess.PIPE, text=True, timeout=300)
    _refused(r, "standard output", "closed")
    assert not (tmp_path / "out").exists()
    if os.path.exists("/dev/full"):
        with open("/dev/full", "w") as full:
            r = _run(_register(rig, rec, tmp_path / "out2"), tmp_path, stdout=full)
        _refused(r, "standard output", "No space left on device")


def test_address_space_limit_is_one_line(tmp_path):
    """``ulimit -v 900000``: a library that cannot be mapped is "out of memory", not an ImportError
    traceback."""
    import resource

    rig, rec = _write_inputs(tmp_path)

    def limit():
        resource.setrlimit(resource.RLIMIT_AS, (900_000 * 1024, 900_000 * 1024))

    r = subprocess.run([sys.executable, "-m", "plantreg_gui", *map(str, _register(rig, rec, tmp_path / "out"))],
                       env=_env(), cwd=tmp_path, capture_output=True, text=True, timeout=300, preexec_fn=limit)
    if r.returncode == 0:
        pytest.fail("the registration fitted in 900 MB of address space: the limit no longer tests anything")
    _refused(r, "memory")
    assert not (tmp_path / "out").exists() and not list(tmp_path.glob(".out.*"))


def test_long_output_names(tmp_path):
    """A 250-character --out (a legal name) is written; a 300-character one is refused naming it,
    never the temporary name (the old code failed the first at its temporary name)."""
    rig, rec = _write_inputs(tmp_path)
    ok = tmp_path / ("o" * 250)
    r = _run(_register(rig, rec, ok), tmp_path)
    assert r.returncode == 0, r.stderr
    assert (ok / "summary.json").is_file() and not [p for p in tmp_path.iterdir() if p.name.startswith(".")]
    long = tmp_path / ("p" * 300)
    _refused_unchanged(tmp_path, _register(rig, rec, long), "ppp", "too long a name for the file system")


def test_no_inodes_left_names_the_users_path(tmp_path, monkeypatch):
    """Out of inodes (or space) while making the temporary output: the message names OUT."""
    import tempfile

    from plantreg_gui.core.io import imageio

    def full(*a, **k):
        raise OSError(errno.ENOSPC, "No space left on device", str(tmp_path / ".out.abcd1234.part"))

    monkeypatch.setattr(tempfile, "mkdtemp", full)
    with pytest.raises(OSError) as e:
        with imageio.atomic_output_dir(tmp_path / "out"):
            pass
    assert e.value.filename == str(tmp_path / "out")


def test_atomic_writers_never_replace_a_special_file(tmp_path):
    """The GUI's saves go through the same writers: a FIFO or a loop is refused, never replaced."""
    from plantreg_gui.core.io.imageio import atomic_write_text

    os.mkfifo(tmp_path / "f.json")
    os.symlink("l.json", tmp_path / "l.json")
    with pytest.raises(InputError, match="FIFO"):
        atomic_write_text(tmp_path / "f.json", "{}")
    with pytest.raises(InputError, match="symbolic link loop"):
        atomic_write_text(tmp_path / "l.json", "{}")
    assert stat.S_ISFIFO(os.lstat(tmp_path / "f.json").st_mode) and os.readlink(tmp_path / "l.json") == "l.json"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["f.json", "l.json"]


def test_batch_paths(tmp_path):
    """A NUL in a list line refuses the list naming its line; a loop as OUT is refused; a loop, a
    FIFO or a device as a recording fails that recording with its own words."""
    rig, rec = _write_inputs(tmp_path)
    (tmp_path / "list.txt").write_text(f"{rec}\nre\u0000c\n")
    base = ["batch", "--rig", rig, "--target", "ir", "--workers", "1", "--quiet"]
    _refused_unchanged(tmp_path, [*base, "--out", tmp_path / "out", tmp_path / "list.txt"], "list.txt",
                       "line 2", "NUL")
    os.symlink("L", tmp_path / "L")
    _refused_unchanged(tmp_path, [*base, "--out", tmp_path / "L", rec], tmp_path / "L", "symbolic link loop")
    os.mkfifo(tmp_path / "F")
    r = _run([*base, "--out", tmp_path / "out", tmp_path / "L", tmp_path / "F", "/dev/zero"], tmp_path)
    assert r.returncode == 1 and "Traceback" not in r.stderr + r.stdout, r.stderr
    for words in ("L: recording folder is a symbolic link loop", "F: recording folder is a FIFO",
                  "/dev/zero: recording folder is a device"):
        assert words in r.stdout, r.stdout


def test_batch_folder_names_equal_but_for_their_unicode_spelling(tmp_path):
    """"Ärger" typed (one code point) and "Ärger" from a macOS file (A + combining diaeresis) look
    the same and would be one OUT/<name> folder on macOS: refused as a clash before any work."""
    rig, rec = _write_inputs(tmp_path)
    shutil.copytree(rec, tmp_path / "\u00c4rger")
    shutil.copytree(rec, tmp_path / "A\u0308rger")
    _refused_unchanged(tmp_path, ["batch", "--rig", rig, "--target", "ir", "--out", tmp_path / "out", "--workers",
                                  "1", "--quiet", tmp_path / "\u00c4rger", tmp_path / "A\u0308rger"], "out", "clash")


# ---------------------------------------------------------------------- 2. one camera-name rule
@pytest.mark.parametrize("name,words", [
    ("../x", "folder separator"), ("a/b", "folder separator"), ("c" * 65, "65 characters"),
    ("a\tb", "control character"), ("th*", "wildcard"), ("th?", "wildcard"), ("w\u00e4rme", "non-ASCII"),
    (".hidden", "hidden"), (" ir2", "leading or trailing space"), ("CON", "device name Windows reserves")])
def test_recording_create_refuses_what_register_refuses(tmp_path, name, words):
    """The manifest ``recording create`` would write is read back by the loader's own rule."""
    rig, rec = _write_inputs(tmp_path)
    _refused_unchanged(tmp_path, ["recording", "create", tmp_path / "new", "--depth", rec / "depth.png",
                                  "--image", f"{name}={rec / 'ir.npy'}"], "camera names are 1 to 64 ASCII", words)


def test_recording_create_refuses_names_equal_ignoring_case(tmp_path):
    rig, rec = _write_inputs(tmp_path)
    _refused_unchanged(tmp_path, ["recording", "create", tmp_path / "new", "--image", f"ir={rec / 'ir.npy'}",
                                  "--image", f"IR={rec / 'ir.npy'}"], '"ir" and "IR"', "case")


@pytest.mark.parametrize("names", [("therm*",), ("w\u00e4rme", "wa\u0308rme")])
def test_rig_names_with_wildcards_or_non_ascii_are_refused(tmp_path, names):
    """``*`` is a wildcard; NFC "wärme" and NFD "wärme" look the same and differ: both refused from
    the rig by the rule's own reason (not "case-insensitive file systems")."""
    rig, rec = _write_inputs(tmp_path)
    for old, new in zip(("thermal", "rgb"), names):
        _rename_camera(rig, rec, old, new)
    err = _refused_unchanged(tmp_path, _register(rig, rec, tmp_path / "out"), rig)
    assert ("wildcard" if "*" in names[0] else "non-ASCII") in err and "case-insensitive" not in err


# ---------------------------------------------------------------------- 3. output names unique
def test_camera_named_like_another_cameras_mask_is_refused(tmp_path):
    """``thermal_edge`` beside ``thermal``: ``cases/thermal_edge.png`` would be both thermal's
    mixed-pixel mask and thermal_edge's case map (the old code wrote it twice and listed it twice
    in summary.json); refused from the rig before any work."""
    rig, rec = _write_inputs(tmp_path)
    d = json.loads(rig.read_text())
    d["cameras"].append(dict(next(c for c in d["cameras"] if c["name"] == "thermal"), name="thermal_edge"))
    rig.write_text(json.dumps(d))
    _manifest(rec, thermal_edge="thermal.tif")
    _refused_unchanged(tmp_path, _register(rig, rec, tmp_path / "out"), rig, "cases/thermal_edge.png",
                       "'thermal'", "'thermal_edge'")


def test_every_output_file_is_declared_in_the_registry(tmp_path):
    """What write_outputs writes is exactly what OUTPUT_PARTS declares (``path``): so the clash
    check, made from the declarations, covers every file, and summary.json lists each once."""
    from test_export import _result

    rig, res = _result()
    out = export.write_outputs(res, rig, None, tmp_path / "out")
    summary = json.loads((out / "summary.json").read_text())
    declared = [p.file(cam) for p in export.OUTPUT_PARTS for step, _ in p.steps(res, export._camera_order(res, rig))
                for cam in [step.partition(":")[2]]]
    assert summary["files"] == declared and len(set(declared)) == len(declared)
    on_disk = sorted(str(p.relative_to(out)) for p in out.rglob("*") if p.is_file())
    assert on_disk == sorted(declared)
