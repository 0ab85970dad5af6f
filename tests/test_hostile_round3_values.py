"""Hostile inputs, round 3 (issue 22), widened: hostile *values* inside the JSON files and images the
commands read, and hostile numbers on the command line -- each class closed where it is parsed
(one validation layer: ``core/io/imageio.read_json``, ``core/validate.py``, the argparse types of
``cli/__init__.py``, the image readers), never case by case.

Every refusal: exit 1 (2 for argparse), exactly one line on stderr naming the file (or option)
and what is wrong, no traceback, no library note (numpy's "overflow encountered", tifffile's log,
libpng's "libpng error"), and the test's folder unchanged. Inputs are generated here. Tests
marked "guard" pass on the code before this change too (they keep an already-correct class
closed); every other test failed on it. ``tests/hostile_paths_probe.py`` runs the wider sweep.
"""

from __future__ import annotations

import json
import shutil
import struct
import subprocess
import sys
import zlib
from pathlib import Path

import numpy as np
import pytest
import tifffile

from test_cli_fit_rig import fit_inputs  # noqa: F401 (fixture)
from test_hostile import _env, _manifest, _write_inputs, tiny_session  # noqa: F401 (fixture)
from test_hostile_round3_paths import _refused_unchanged, _run, _snapshot, fit_copy  # noqa: F401 (fixture)

W, H = 40, 30  # test_hostile's depth camera


def _register(rig, rec, out, *extra):
    return ["register", "--rig", rig, "--recording", rec, "--target", "ir", "--out", out, "--quiet", *extra]


def _edit(path: Path, fn) -> None:
    d = json.loads(path.read_text())
    fn(d)
    path.write_text(json.dumps(d))  # NaN and Infinity as Python writes them (not JSON, but what users meet)


def _ok(r: subprocess.CompletedProcess) -> None:
    assert r.returncode == 0, (r.returncode, r.stderr)
    assert "Traceback" not in r.stderr


# ---------------------------------------------------------------------- JSON files as a whole
@pytest.mark.parametrize("which", ["rig", "recording.json"])
def test_a_key_given_twice_is_refused(tmp_path, which):
    """``{"depth": ..., ..., "depth": ...}``: Python's reader kept the last silently (others keep the
    first), so the run went on with one reading of an ambiguous file; now refused naming the key."""
    rig, rec = _write_inputs(tmp_path)
    f = rig if which == "rig" else rec / "recording.json"
    text = f.read_text()
    key = next(iter(json.loads(text)))
    f.write_text("{" + json.dumps({key: "first"})[1:-1] + ", " + text.strip()[1:])
    _refused_unchanged(tmp_path, _register(rig, rec, tmp_path / "out"), f, f"'{key}' appears twice")


@pytest.mark.parametrize("encoding", ["utf-8-sig", "utf-16", "utf-32"])
def test_json_with_a_byte_order_mark_or_in_utf16_is_read(tmp_path, encoding):
    """Windows editors save UTF-8 with a byte-order mark, some tools UTF-16; RFC 8259 readers
    accept them (they were refused as 'Unexpected UTF-8 BOM' / 'not UTF-8 text')."""
    rig, rec = _write_inputs(tmp_path)
    for f in (rig, rec / "recording.json"):
        f.write_bytes(f.read_text().encode(encoding))
    _ok(_run(_register(rig, rec, tmp_path / "out"), tmp_path))
    assert (tmp_path / "out" / "summary.json").is_file()


_CORRUPT = {
    "empty": b"", "text": b"not json\n", "binary": bytes(range(256)), "top-level list": b"[1, 2]",
    "NaN alone": b"NaN", "deep lists": b"[" * 100000 + b"]" * 100000, "trailing garbage": b'{"a": 1} }}',
}


@pytest.mark.parametrize("corruption", list(_CORRUPT))
@pytest.mark.parametrize("which", ["rig", "recording.json"])
def test_guard_corrupt_json_is_one_line_naming_the_file(tmp_path, which, corruption):
    """Guard: already refused cleanly before; kept closed for both files register reads."""
    rig, rec = _write_inputs(tmp_path)
    f = rig if which == "rig" else rec / "recording.json"
    f.write_bytes(_CORRUPT[corruption])
    _refused_unchanged(tmp_path, _register(rig, rec, tmp_path / "out"), f)


# ---------------------------------------------------------------------- values inside the files
def test_a_recording_depth_scale_of_1e308_is_refused_naming_it(tmp_path):
    """The one depth-scale rule (0 < s <= 1000 m per unit) holds for a recording's own scale as for
    the rig's: 1e308 used to overflow into 'no surface inside the region of interest' naming the
    depth map, after numpy's overflow notes."""
    rig, rec = _write_inputs(tmp_path)
    _edit(rec / "recording.json", lambda m: m.update(depth_scale=1e308))
    _refused_unchanged(tmp_path, _register(rig, rec, tmp_path / "out"), rec / "recording.json", "depth_scale",
                       "at most 1000")


def test_recording_create_depth_scale_follows_the_same_rule(tmp_path):
    """``recording create --depth-scale 1e308`` wrote a manifest (exit 0) that no rig can use."""
    _rig, rec = _write_inputs(tmp_path)
    _refused_unchanged(tmp_path, ["recording", "create", tmp_path / "new", "--depth", rec / "depth.png",
                                  "--depth-scale", "1e308"], "--depth-scale", "at most 1000")


def test_session_depth_scale_and_square_size_name_session_json(tmp_path, tiny_session):
    """A session's depth.scale of 1e308 was refused late without naming any file; a board square of
    1e308 m ended in an OpenCV assertion. Both are now refused at loading, naming session.json."""
    s = shutil.copytree(tiny_session, tmp_path / "s")
    argv = ["calibrate", s, "--out", tmp_path / "o.json", "--report", tmp_path / "r.json", "--quiet"]
    _edit(s / "session.json", lambda d: d["depth"].update(scale=1e308))
    _refused_unchanged(tmp_path, argv, s / "session.json", "depth.scale")
    _edit(s / "session.json", lambda d: (d["depth"].update(scale=0.001), d["board"].update(square_size=1e308)))
    _refused_unchanged(tmp_path, argv, s / "session.json", "square_size")


def test_session_review_of_the_wrong_type_is_refused(tmp_path, tiny_session):
    """``"review": []`` was taken for 'no review' (an empty list is false); a wrong type is refused."""
    s = shutil.copytree(tiny_session, tmp_path / "s")
    _edit(s / "session.json", lambda d: d.update(review=[]))
    _refused_unchanged(tmp_path, ["calibrate", s, "--out", tmp_path / "o.json", "--report", tmp_path / "r.json",
                                  "--quiet"], s / "session.json", "review")


def test_an_unknown_camera_in_recording_json_names_the_manifest(tmp_path):
    """The camera name is a key of recording.json: named there, not as the image file it points at."""
    rig, rec = _write_inputs(tmp_path)
    _manifest(rec, lidar="thermal.tif")
    _refused_unchanged(tmp_path, _register(rig, rec, tmp_path / "out"), rec / "recording.json", "images.lidar")


def test_overflowing_distortion_is_one_line(tmp_path):
    """``dist: [1e308, ...]`` was refused after two lines of numpy overflow notes."""
    rig, rec = _write_inputs(tmp_path)
    _edit(rig, lambda d: d["cameras"][1].update(dist=[1e308] * 5))
    _refused_unchanged(tmp_path, _register(rig, rec, tmp_path / "out"), rig, "cameras[1].dist")


# ---------------------------------------------------------------------- images
def _png(path: Path, w: int, h: int, ctype: int, idat: bytes, plte: bool = False) -> None:
    def chunk(k: bytes, d: bytes) -> bytes:
        return struct.pack(">I", len(d)) + k + d + struct.pack(">I", zlib.crc32(k + d) & 0xFFFFFFFF)

    body = b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, ctype, 0, 0, 0))
    if plte:
        body += chunk(b"PLTE", bytes(range(48)))
    path.write_bytes(body + chunk(b"IDAT", zlib.compress(idat)) + chunk(b"IEND", b""))


def _tiff_claiming(path: Path, w: int, h: int) -> None:
    tifffile.imwrite(path, np.zeros((4, 4), np.uint16))
    b = bytearray(path.read_bytes())
    with tifffile.TiffFile(path) as t:
        for name, val in (("ImageWidth", w), ("ImageLength", h)):
            tg = t.pages[0].tags[name]
            size = 2 if tg.dtype == 3 else 4
            b[tg.valueoffset:tg.valueoffset + size] = val.to_bytes(size, "little")
    path.write_bytes(bytes(b))


@pytest.mark.parametrize("kind", ["palette PNG with short pixel data", "grey PNG with short pixel data",
                                  "TIFF claiming 100000 x 100000", "text named .tif"])
def test_broken_images_are_one_line_without_library_notes(tmp_path, kind):
    """libpng ("libpng error: Not enough image data") and tifffile (its log) printed their own line
    before plantreg's: two lines, one of them without the file's name."""
    rig, rec = _write_inputs(tmp_path)
    if kind.startswith("palette"):
        _png(rec / "depth.png", W, H, 3, b"\x00" * 64, plte=True)
        f = rec / "depth.png"
    elif kind.startswith("grey"):
        _png(rec / "rgb.png", 80, 60, 0, b"\x00" * 64)
        f = rec / "rgb.png"
    elif kind.startswith("TIFF"):
        _tiff_claiming(rec / "thermal.tif", 100000, 100000)
        f = rec / "thermal.tif"
    else:
        (rec / "thermal.tif").write_text("II*\x00 not really a TIFF")
        f = rec / "thermal.tif"
    _refused_unchanged(tmp_path, _register(rig, rec, tmp_path / "out"), f)


def test_an_all_infinite_float_depth_map_is_empty(tmp_path):
    """An infinite depth is no measurement, as 0 and NaN are: a depth map of +inf is 'empty'
    (it passed as 'has depth > 0' and failed later, after numpy's overflow notes)."""
    rig, rec = _write_inputs(tmp_path)
    tifffile.imwrite(rec / "depth.tif", np.full((H, W), np.inf, np.float32))
    _manifest(rec, depth="depth.tif")
    _refused_unchanged(tmp_path, _register(rig, rec, tmp_path / "out"), rec / "depth.tif", "empty")


def test_a_float_depth_map_with_inf_holes_registers_like_nan_holes(tmp_path):
    """+inf where nothing was measured gives the result NaN there gives (it was taken for a depth)."""
    rig, rec = _write_inputs(tmp_path)
    d = np.full((H, W), 1.0, np.float32)
    d[::3] = np.nan
    results = {}
    for hole in ("nan", "inf"):
        d2 = d.copy()
        if hole == "inf":
            d2[np.isnan(d2)] = np.inf
        tifffile.imwrite(rec / "depth.tif", d2)
        _manifest(rec, depth="depth.tif")
        _edit(rec / "recording.json", lambda m: m.update(depth_scale=1.0))
        _ok(_run(_register(rig, rec, tmp_path / hole), tmp_path))
        results[hole] = tifffile.imread(tmp_path / hole / "registered" / "thermal.tif")
    np.testing.assert_array_equal(results["nan"], results["inf"])


# ---------------------------------------------------------------------- numbers on the command line
_IR = "ir=infrared,640x576,f=504,rot=0"


@pytest.mark.parametrize("spec, extra, words", [
    ("rgb=rgb,100000x100000,hfov=90,rot=0", (), ("--camera 'rgb'", "width", "65536")),
    ("rgb=rgb,1280x720,f=1e308,rot=0", (), ("--camera 'rgb'", "fx")),
    ("a/b=rgb,1280x720,hfov=90,rot=0", (), ("a/b", "folder separator")),
    ("a\nb=rgb,1280x720,hfov=90,rot=0", (), ("U+000A",)),
    ("rgb=rgb,1280x720,hfov=90,rot=0", ("--roi", "0,0,0,inf,1,1"), ("--roi", "finite")),
    ("rgb=rgb,1280x720,hfov=90,rot=0", ("--depth-scale", "1e308"), ("--depth-scale", "at most 1000")),
])
def test_rig_create_refuses_what_the_rig_reader_refuses(tmp_path, spec, extra, words):
    """``rig create`` wrote rigs (exit 0) that ``register`` then refused: a 100000-pixel side, a
    focal length of 1e308, a camera named ``a/b`` or with a newline, an infinite ROI. The rig it
    builds now passes the rig reader's own checks, named by the option that gave the value."""
    _refused_unchanged(tmp_path, ["rig", "create", tmp_path / "rig.json", "--depth-camera", "ir", "--camera", _IR,
                                  "--camera", spec, *extra], words[0], *words[1:])


@pytest.mark.parametrize("extra, option", [
    (("--worst", "-1"), "--worst"), (("--max-median", "inf"), "--max-median"),
    (("--prior", "robust=1e308"), "robust"), (("--prior", "rotation=1000"), "rotation"),
])
def test_fit_rig_numbers(fit_copy, extra, option):  # noqa: F811
    """``--worst -1`` listed all but the last landmark (a Python slice) and ``--max-median inf``
    switched the quality gate off, both exit 0; ``--prior robust=1e308`` overflowed the solver
    (a traceback). Refused: argparse types (exit 2) and the priors' bounds (exit 1)."""
    before = _snapshot(fit_copy)
    r = _run(["fit-rig", "--rig", fit_copy / "start.json", "--landmarks", fit_copy / "landmarks.json", "--out",
              fit_copy / "o.json", "--quiet", *extra], fit_copy)
    assert r.returncode in (1, 2) and "Traceback" not in r.stderr, (r.returncode, r.stderr)
    assert option in r.stderr.strip().splitlines()[-1], r.stderr
    assert _snapshot(fit_copy) == before


def test_batch_workers_beyond_any_machine(tmp_path):
    """``--workers 100000000000000000000`` ran (exit 0), silently capped."""
    rig, rec = _write_inputs(tmp_path)
    _refused_unchanged(tmp_path, ["batch", "--rig", rig, "--target", "ir", "--out", tmp_path / "out", "--workers",
                                  str(10 ** 20), "--quiet", rec], "--workers", "1024")


# ---------------------------------------------------------------------- batch rows and odd names
def test_a_failed_batch_row_names_the_recording_once(tmp_path):
    """``failed X: X: recording folder is a symbolic link loop`` said X twice; and a recording folder
    with a newline in its name broke the line in two."""
    import os

    rig, rec = _write_inputs(tmp_path)
    os.symlink("L", tmp_path / "L")
    odd = tmp_path / "re\nc"
    shutil.copytree(rec, odd)
    (odd / "thermal.tif").write_bytes(b"")
    r = _run(["batch", "--rig", rig, "--target", "ir", "--out", tmp_path / "out", "--workers", "1", "--quiet",
              tmp_path / "L", odd], tmp_path)
    assert r.returncode == 1 and "Traceback" not in r.stderr, r.stderr
    failed = [line for line in r.stdout.splitlines() if line.lstrip().startswith("failed")]
    assert len(failed) == 2, r.stdout
    loop = next(line for line in failed if "/L:" in line)
    assert loop.count(str(tmp_path / "L")) == 1 and "symbolic link loop" in loop, loop
    newline = next(line for line in failed if "re\\nc" in line)
    assert "thermal.tif: image file is empty" in newline and newline.count("re\\nc") == 1, newline


# ---------------------------------------------------------------------- numbers and names beyond the usual
@pytest.mark.parametrize("digits", [400, 5000])
@pytest.mark.parametrize("which", ["rig", "recording.json"])
def test_whole_numbers_beyond_a_float_are_refused(tmp_path, which, digits):
    """A JSON integer of 400 digits ended in ``OverflowError: int too large to convert to float``,
    one of 5000 in Python's own ``ValueError: Exceeds the limit (4300 digits)``: tracebacks."""
    rig, rec = _write_inputs(tmp_path)
    f, key = (rig, "width") if which == "rig" else (rec / "recording.json", "depth_scale")
    if which == "rig":
        _edit(f, lambda d: d["cameras"][0].update(width=123456789))
    else:
        _edit(f, lambda d: d.update(depth_scale=123456789))
    f.write_text(f.read_text().replace("123456789", "1" + "0" * (digits - 1)))
    _refused_unchanged(tmp_path, _register(rig, rec, tmp_path / "out"), f, f"{digits} digits")


def test_a_recording_folder_name_that_is_not_utf8_is_registered_and_tabled(tmp_path):
    """A folder name with a byte that is not UTF-8 (Python holds it as a surrogate): batch ended in
    ``UnicodeEncodeError`` writing batch.csv, after registering. The table now names the folder by
    its own bytes."""
    import os

    rig, rec = _write_inputs(tmp_path)
    odd = tmp_path / os.fsdecode(b"re\xffc")
    shutil.move(rec, odd)
    r = _run(["batch", "--rig", rig, "--target", "ir", "--out", tmp_path / "out", "--workers", "1", "--quiet", odd],
             tmp_path, errors="surrogateescape")
    _ok(r)
    table = (tmp_path / "out" / "batch.csv").read_bytes()
    assert b"re\xffc,done" in table and (tmp_path / "out" / odd.name / "summary.json").is_file()


def test_a_landmarks_file_of_tens_of_thousands_of_points_is_refused(fit_copy):  # noqa: F811
    """12 points repeated to 30,000 per recording: fit-rig ran for many minutes (a hang to its
    user); landmarks are clicked by hand, so a file beyond 10,000 points is refused at once."""
    f = fit_copy / "landmarks.json"
    _edit(f, lambda d: [v.update(points=v["points"] * 2500) for v in d["recordings"].values()])
    _refused_unchanged(fit_copy, ["fit-rig", "--rig", fit_copy / "start.json", "--landmarks", f, "--out",
                                  fit_copy / "o.json", "--quiet"], f, "10000 points")
