"""Hostile pass, round 4 (issue 22, an outside tester's classes the first probe does not hold), as a
script. Same verdicts as ``hostile_paths_probe.py`` (clean, ok, VAGUE, MISHANDLED), and the run
itself may be hostile: an environment (HOME unset, LANG=C, an unwritable TMPDIR, an ASCII-only
standard stream), a resource limit (file size: ``ulimit -f``), a closed stdin/stderr, a reader that
goes away (``| head -c1``), a signal at a moment (to the process or its group, once or twice), or a
second command writing into the same folder at the same time.

    python tests/hostile_round4_probe.py SOURCE_TREE [NAME_FILTER ...]   (HP_ROOT=/tmp/hp4 by default)
"""
import json, os, re, shutil, signal, subprocess, sys, tempfile, time, random
from pathlib import Path

os.environ.setdefault("HP_ROOT", "/tmp/hp4")
_argv = sys.argv
sys.argv = [_argv[0], _argv[1], "__none__"]
sys.path.insert(0, str(Path(__file__).resolve().parent))
import hostile_paths_probe as hp  # noqa: E402  (its helpers and fixtures; its own cases are not run)
from hostile_paths_probe import mkrec, mkfit, reg, fit, bat, rc, _imgs, _cal, _edit, _manifest, snapshot  # noqa: E402
sys.argv = _argv
import numpy as np, cv2, tifffile  # noqa: E402

ROOT = hp.ROOT
PY = sys.executable
SRC = sys.argv[1]
only = sys.argv[2:]
W, H = hp.W, hp.H

CASES = []


def case(expect="refuse"):
    def deco(f):
        CASES.append((f.__name__, f, expect)); return f
    return deco


class Run(dict):
    """What a case asks for: argv, culprit words, and how the run is made hostile."""


def R(argv, culprit=None, **kw):
    return Run(argv=argv, culprit=culprit, **kw)


# ======================================================================= images that lie
def _npy_header(path, descr, shape, fortran=False, data=b"", version=(1, 0)):
    hdr = "{'descr': %r, 'fortran_order': %s, 'shape': %r, }" % (descr, fortran, tuple(shape))
    if version == (1, 0):
        hdr = hdr.ljust((len(hdr) + 11 + 63) // 64 * 64 - 11) + "\n"
        b = b"\x93NUMPY\x01\x00" + len(hdr).to_bytes(2, "little") + hdr.encode("latin1")
    else:
        hdr = hdr.ljust((len(hdr) + 13 + 63) // 64 * 64 - 13) + "\n"
        b = b"\x93NUMPY" + bytes(version) + len(hdr).to_bytes(4, "little") + hdr.encode("utf8")
    Path(path).write_bytes(b + data)


def _pickle_bomb(p):
    import pickle
    class Evil:
        def __reduce__(self):
            return (os.system, (f"touch {p.parent}/PWNED",))
    arr = np.empty((1,), object); arr[0] = Evil()
    with open(p, "wb") as f:
        np.lib.format.write_array(f, arr, allow_pickle=True)


def _tiff_tags_forged(path, arr, **tags):
    tifffile.imwrite(path, arr)
    b = bytearray(Path(path).read_bytes())
    with tifffile.TiffFile(path) as t:
        tg = t.pages[0].tags
        for name, val in tags.items():
            x = tg[name]; off = x.valueoffset; size = {3: 2, 4: 4}.get(x.dtype, 2)
            b[off:off + size] = int(val).to_bytes(size, "little")
    Path(path).write_bytes(bytes(b))


IMG = {
    # ir.npy (the infrared image, an .npy)
    "npy_pickle_exec": ("ir.npy", _pickle_bomb, "refuse", "ir.npy"),
    "npy_bigendian_u16": ("ir.npy", lambda p: np.save(p, np.full((H, W), 300, ">u2")), "ok", None),
    "npy_fortran": ("ir.npy", lambda p: np.save(p, np.asfortranarray(np.full((H, W), 300, np.uint16))), "ok", None),
    "npy_float16": ("ir.npy", lambda p: np.save(p, np.full((H, W), 3, np.float16)), "ok", None),
    "npy_int64_huge": ("ir.npy", lambda p: np.save(p, np.full((H, W), 2**62, np.int64)), "ok", None),
    "npy_uint64_max": ("ir.npy", lambda p: np.save(p, np.full((H, W), 2**64 - 1, np.uint64)), "ok", None),
    "npy_float_nan_all": ("ir.npy", lambda p: np.save(p, np.full((H, W), np.nan, np.float32)), "ok", None),
    "npy_shape_zero": ("ir.npy", lambda p: np.save(p, np.zeros((0, W), np.uint16)), "refuse", "ir.npy"),
    "npy_shape_zero_w": ("ir.npy", lambda p: np.save(p, np.zeros((H, 0), np.uint16)), "refuse", "ir.npy"),
    "npy_1d": ("ir.npy", lambda p: np.save(p, np.zeros((W * H,), np.uint16)), "refuse", "ir.npy"),
    "npy_bomb_header": ("ir.npy", lambda p: _npy_header(p, "<u2", (1 << 20, 1 << 20)), "refuse", "ir.npy"),
    "npy_bomb_bands": ("ir.npy", lambda p: _npy_header(p, "<u2", (H, W, 1 << 30)), "refuse", "ir.npy"),
    "npy_neg_shape": ("ir.npy", lambda p: _npy_header(p, "<u2", (-1, W)), "refuse", "ir.npy"),
    "npy_header_garbage": ("ir.npy", lambda p: p.write_bytes(b"\x93NUMPY\x01\x00\x10\x00{'descr': bad}  \n"), "refuse", "ir.npy"),
    "npy_header_code": ("ir.npy", lambda p: _npy_header(p, "__import__('os').system('touch PWNED')", (H, W)), "refuse", "ir.npy"),
    "npy_v3_header": ("ir.npy", lambda p: _npy_header(p, "<u2", (H, W), data=b"\x00" * (2 * H * W), version=(3, 0)), "ok", None),
    "npy_v9_header": ("ir.npy", lambda p: _npy_header(p, "<u2", (H, W), data=b"\x00" * (2 * H * W), version=(9, 0)), "refuse", "ir.npy"),
    "npy_truncated_half": ("ir.npy", lambda p: p.write_bytes(p.read_bytes()[: 128 + H * W]), "refuse", "ir.npy"),
    "npy_is_npz": ("ir.npy", lambda p: (np.savez(str(p) + ".npz", a=np.zeros((H, W))), os.replace(str(p) + ".npz", p)), "refuse", "ir.npy"),
    "npy_structured": ("ir.npy", lambda p: np.save(p, np.zeros((H, W), [("a", "<u2"), ("b", "<f4")])), "refuse", "ir.npy"),
    "npy_subarray_dtype": ("ir.npy", lambda p: _npy_header(p, [("", "<u2", (2,))], (H, W), data=b"\x00" * (4 * H * W)), "refuse", "ir.npy"),
    "npy_void": ("ir.npy", lambda p: np.save(p, np.zeros((H, W), "V4")), "refuse", "ir.npy"),
    "npy_datetime": ("ir.npy", lambda p: np.save(p, np.zeros((H, W), "M8[s]")), "refuse", "ir.npy"),
    "npy_str": ("ir.npy", lambda p: np.save(p, np.full((H, W), "a")), "refuse", "ir.npy"),
    "npy_5bands": ("ir.npy", lambda p: np.save(p, np.ones((H, W, 5), np.uint16)), "refuse", "ir.npy"),
    "npy_trailing_bytes": ("ir.npy", lambda p: p.write_bytes(p.read_bytes() + b"\x00" * 1000), "ok", None),
    "npy_empty_file": ("ir.npy", lambda p: p.write_bytes(b""), "refuse", "ir.npy"),
    "npy_magic_only": ("ir.npy", lambda p: p.write_bytes(b"\x93NUMPY"), "refuse", "ir.npy"),
    # thermal.tif
    "tif_multipage_diff_sizes": ("thermal.tif", lambda p: (tifffile.imwrite(p, np.ones((24, 32), np.float32)), tifffile.imwrite(p, np.ones((5, 7), np.float32), append=True)), "ok", None),
    "tif_zero_width_tag": ("thermal.tif", lambda p: _tiff_tags_forged(p, np.ones((24, 32), np.uint16), ImageWidth=0), "refuse", "thermal.tif"),
    "tif_zero_height_tag": ("thermal.tif", lambda p: _tiff_tags_forged(p, np.ones((24, 32), np.uint16), ImageLength=0), "refuse", "thermal.tif"),
    "tif_bits_lie": ("thermal.tif", lambda p: _tiff_tags_forged(p, np.ones((24, 32), np.uint16), BitsPerSample=64), "refuse", "thermal.tif"),
    "tif_huge_compressed": ("thermal.tif", lambda p: tifffile.imwrite(p, np.zeros((20000, 20000), np.uint8), compression="zlib", tile=(1024, 1024)), "refuse", "thermal.tif"),
    "tif_int8": ("thermal.tif", lambda p: tifffile.imwrite(p, np.full((24, 32), -5, np.int8)), "ok", None),
    "tif_uint32": ("thermal.tif", lambda p: tifffile.imwrite(p, np.full((24, 32), 2**31, np.uint32)), "ok", None),
    "tif_float16": ("thermal.tif", lambda p: tifffile.imwrite(p, np.full((24, 32), 21.5, np.float16)), "ok", None),
    "tif_bool": ("thermal.tif", lambda p: tifffile.imwrite(p, np.ones((24, 32), bool)), "ok", None),
    "tif_2ch": ("thermal.tif", lambda p: tifffile.imwrite(p, np.ones((24, 32, 2), np.uint8), photometric="minisblack", planarconfig="contig"), "ok", None),
    "tif_planar_rgb": ("thermal.tif", lambda p: tifffile.imwrite(p, np.ones((3, 24, 32), np.uint8), photometric="rgb", planarconfig="separate"), "ok", None),
    "tif_bigtiff": ("thermal.tif", lambda p: tifffile.imwrite(p, np.full((24, 32), 21.5, np.float32), bigtiff=True), "ok", None),
    "tif_jpeg_compressed": ("thermal.tif", lambda p: tifffile.imwrite(p, np.full((24, 32), 100, np.uint8), compression="jpeg"), "ok", None),
    "tif_lzw_truncated": ("thermal.tif", lambda p: (tifffile.imwrite(p, np.random.default_rng(1).random((24, 32)).astype(np.float32), compression="lzw"), p.write_bytes(p.read_bytes()[:-1500])), "refuse", "thermal.tif"),
    "tif_volume_1page": ("thermal.tif", lambda p: tifffile.imwrite(p, np.ones((1, 24, 32), np.float32)), "ok", None),
    "tif_imagej_hyperstack": ("thermal.tif", lambda p: tifffile.imwrite(p, np.ones((2, 3, 24, 32), np.float32), imagej=True), "refuse", "thermal.tif"),
    "tif_offset_loop": ("thermal.tif", lambda p: (tifffile.imwrite(p, np.ones((24, 32), np.float32)), _ifd_loop(p)), "ok", None),
    "tif_complex128": ("thermal.tif", lambda p: tifffile.imwrite(p, np.ones((24, 32), np.complex128)), "refuse", "complex"),
    "tif_float_huge_vals": ("thermal.tif", lambda p: tifffile.imwrite(p, np.full((24, 32), 3e38, np.float32)), "ok", None),
    # rgb.png
    "png_1bit": ("rgb.png", lambda p: hp._png_forged_size(p, 80, 60, 1, 0), "refuse", "rgb.png"),
    "png_16bit_gray_alpha": ("rgb.png", lambda p: cv2.imwrite(str(p), np.full((60, 80, 2), 7, np.uint16)) if False else _png_ga(p), "ok", None),
    "png_interlaced": ("rgb.png", lambda p: _pil_save(p, np.full((60, 80, 3), 9, np.uint8), interlace=1), "ok", None),
    "png_zero_size": ("rgb.png", lambda p: hp._png_forged_size(p, 0, 0), "refuse", "rgb.png"),
    "png_apng": ("rgb.png", lambda p: _apng(p), "ok", None),
    "png_trailing_garbage": ("rgb.png", lambda p: p.write_bytes(p.read_bytes() + b"garbage" * 100), "ok", None),
    "png_is_gif": ("rgb.png", lambda p: _pil_save(p, np.zeros((60, 80), np.uint8), fmt="GIF"), "refuse", "rgb.png"),
    "png_is_bmp": ("rgb.png", lambda p: _pil_save(p, np.zeros((60, 80, 3), np.uint8), fmt="BMP"), "refuse", "rgb.png"),
    "png_is_webp": ("rgb.png", lambda p: p.write_bytes(cv2.imencode(".webp", np.zeros((60, 80, 3), np.uint8))[1].tobytes()), "refuse", "rgb.png"),
    "png_jpeg_truncated": ("rgb.png", lambda p: p.write_bytes(cv2.imencode(".jpg", np.zeros((60, 80, 3), np.uint8))[1].tobytes()[:200]), "refuse", "rgb.png"),
    "png_huge_zlib_bomb": ("rgb.png", lambda p: _png_bomb(p), "refuse", "rgb.png"),
    # depth.png
    "depth_8bit": ("depth.png", lambda p: cv2.imwrite(str(p), np.full((H, W), 200, np.uint8)), "ok", None),
    "depth_16bit_gray_alpha": ("depth.png", lambda p: _png_ga(p, (H, W)), "refuse", "depth.png"),
    "depth_wrong_size": ("depth.png", lambda p: cv2.imwrite(str(p), np.full((H + 1, W), 1000, np.uint16)), "refuse", "depth.png"),
    "depth_transposed": ("depth.png", lambda p: cv2.imwrite(str(p), np.full((W, H), 1000, np.uint16)), "refuse", "depth.png"),
    "depth_all_max": ("depth.png", lambda p: cv2.imwrite(str(p), np.full((H, W), 65535, np.uint16)), "ok", None),
    "depth_single_valid_px": ("depth.png", lambda p: cv2.imwrite(str(p), _one_px()), "ok", None),
}


def _one_px():
    d = np.zeros((H, W), np.uint16); d[5, 5] = 1000; return d


def _ifd_loop(p):
    """The first IFD's next-IFD offset points back at itself (a page loop)."""
    b = bytearray(p.read_bytes()); off = int.from_bytes(b[4:8], "little"); n = int.from_bytes(b[off:off + 2], "little")
    nxt = off + 2 + 12 * n; b[nxt:nxt + 4] = off.to_bytes(4, "little"); p.write_bytes(bytes(b))


def _pil_save(p, arr, fmt="PNG", **kw):
    from PIL import Image
    Image.fromarray(arr).save(p, format=fmt, **kw)


def _png_ga(p, shape=(60, 80)):
    from PIL import Image
    Image.fromarray(np.full(shape + (2,), 7, np.uint8), "LA").save(p, format="PNG")


def _apng(p):
    from PIL import Image
    fr = [Image.fromarray(np.full((60, 80, 3), i * 40, np.uint8)) for i in range(3)]
    fr[0].save(p, format="PNG", save_all=True, append_images=fr[1:])


def _png_bomb(p):
    """A PNG whose header says 60000x60000 RGB and whose IDAT is a zlib bomb (valid CRCs)."""
    import struct, zlib
    def chunk(k, d): return struct.pack(">I", len(d)) + k + d + struct.pack(">I", zlib.crc32(k + d) & 0xFFFFFFFF)
    z = zlib.compressobj(9); data = b"".join(z.compress(b"\x00" * (1 << 20)) for _ in range(64)) + z.flush()
    p.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", 60000, 60000, 8, 2, 0, 0, 0))
                  + chunk(b"IDAT", data) + chunk(b"IEND", b""))


for nm, (fn, writer, exp, word) in IMG.items():
    def f(r, fn=fn, writer=writer, exp=exp, word=word):
        rig, rec = mkrec(r); writer(rec / fn)
        return R(reg(rig, rec, r / "out"), None if exp == "ok" else (fn, word), no_file="PWNED")
    f.__name__ = f"img4_{nm}"; case(exp)(f)
# the same lies in recording create (which reads every image in full) and in a calibration session
for nm in ("npy_pickle_exec", "npy_bomb_header", "npy_neg_shape", "npy_truncated_half", "npy_structured", "npy_is_npz"):
    fn, writer, exp, word = IMG[nm]
    def f(r, writer=writer, exp=exp, word=word):
        _imgs(r); p = r / "ir.npy"; np.save(p, np.ones((H, W), np.uint16)); writer(p)
        return R(rc(r / "rec", "--image", f"ir={p}"), "ir.npy", no_file="PWNED")
    f.__name__ = f"img4_rc_{nm}"; case()(f)
for nm in ("tif_zero_width_tag", "tif_huge_compressed", "tif_lzw_truncated", "tif_imagej_hyperstack"):
    fn, writer, exp, word = IMG[nm]
    def f(r, writer=writer):
        _imgs(r); p = r / "t.tif"; writer(p); return R(rc(r / "rec", "--image", f"thermal={p}"), "t.tif")
    f.__name__ = f"img4_rc_{nm}"; case()(f)
for nm in ("png_1bit", "png_zero_size", "png_is_gif", "png_is_webp", "png_huge_zlib_bomb", "png_jpeg_truncated"):
    fn, writer, exp, word = IMG[nm]
    def f(r, writer=writer):
        a = _cal(r); img = sorted((r / "s" / "pose_01").glob("rgb.*"))[0]; writer(img); return R(a, img.name)
    f.__name__ = f"img4_cal_{nm}"; case()(f)


# ======================================================================= JSON values, new ones
def _j(r, which):
    return hp.JSON_FILES[which](r)


VALS4 = [
    # rig
    ("rig", lambda d: d["cameras"].append(dict(d["cameras"][1])), ("rig.json", "thermal")),  # same camera twice
    ("rig", lambda d: d["cameras"][1].update(name="ir"), ("rig.json", "ir")),
    ("rig", lambda d: d["cameras"][1].update(name="IR"), ("rig.json", "IR")),
    ("rig", lambda d: d["cameras"][1].update(name="th\u00e9rmal"), ("rig.json", "th")),
    ("rig", lambda d: d["cameras"][1].update(name="the\u0301rmal"), ("rig.json", "th")),
    ("rig", lambda d: d["cameras"][1].update(name="thermal\u200b"), ("rig.json", "thermal")),  # zero-width space
    ("rig", lambda d: d["cameras"][1].update(name="\uff54hermal"), ("rig.json", "hermal")),  # fullwidth t
    ("rig", lambda d: d["cameras"][1].update(name=""), ("rig.json", "name")),
    ("rig", lambda d: d["cameras"][1].update(name=" "), ("rig.json", "name")),
    ("rig", lambda d: d["cameras"][1].update(name="con"), None),  # a Windows device name: documented? valid
    ("rig", lambda d: d["cameras"][1].update(name=["thermal"]), ("rig.json", "name")),
    ("rig", lambda d: d["cameras"][1].update(name={"a": 1}), ("rig.json", "name")),
    ("rig", lambda d: d["cameras"][1].update(width=2**64), ("rig.json", "width")),
    ("rig", lambda d: d["cameras"][1].update(width=-2**63), ("rig.json", "width")),
    ("rig", lambda d: d["cameras"][1].update(width=32.0), None),
    ("rig", lambda d: d["cameras"][1].update(width=1e-320), ("rig.json", "width")),
    ("rig", lambda d: d["cameras"][1].update(height=0), ("rig.json", "height")),
    ("rig", lambda d: d["cameras"][1].update(K=[[30, 0, 16], [0, 30, 12], [0, 0, 0]]), ("rig.json", "K")),
    ("rig", lambda d: d["cameras"][1].update(K=[[-30, 0, 16], [0, -30, 12], [0, 0, 1]]), ("rig.json", "K")),
    ("rig", lambda d: d["cameras"][1].update(K=[[30, 0, 16], [0, 30, 12], [0, 0, 1], [0, 0, 0]]), ("rig.json", "K")),
    ("rig", lambda d: d["cameras"][1].update(K=[[[30]]]), ("rig.json", "K")),
    ("rig", lambda d: d["cameras"][1].update(K=[[30, 0, 16], [0, 30, 12], [0, 0, "1"]]), ("rig.json", "K")),
    ("rig", lambda d: d["cameras"][1].update(K=[[30, 0, 16], [0, 30, 12], [0, 0, True]]), ("rig.json", "K")),
    ("rig", lambda d: d["cameras"][1].update(K=[[30, 0, 16], [0, 30, 12], [0, 0, None]]), ("rig.json", "K")),
    ("rig", lambda d: d["cameras"][1].update(dist=[]), None),
    ("rig", lambda d: d["cameras"][1].update(dist=[[0, 0, 0, 0, 0]]), ("rig.json", "dist")),
    ("rig", lambda d: d["cameras"][1].update(dist=[0, 0, 0, 0, None]), ("rig.json", "dist")),
    ("rig", lambda d: d["cameras"][1].update(R=[[1, 0, 0], [0, 1, 0], [0, 0, -1]]), ("rig.json", "R")),  # a reflection
    ("rig", lambda d: d["cameras"][1].update(R=[[1, 0, 0], [0, 1, 0]]), ("rig.json", "R")),
    ("rig", lambda d: d["cameras"][1].update(R=[]), ("rig.json", "R")),
    ("rig", lambda d: d["cameras"][1].update(t=[]), ("rig.json", "t")),
    ("rig", lambda d: d["cameras"][1].update(t=[0, 0, 0, 0]), ("rig.json", "t")),
    ("rig", lambda d: d["cameras"][1].update(t=[True, 0, 0]), ("rig.json", "t")),
    ("rig", lambda d: d["cameras"][1].update(modality=""), ("rig.json", "modality")),
    ("rig", lambda d: d["cameras"][1].update(modality="x" * 100000), ("rig.json", "modality")),
    ("rig", lambda d: d["cameras"][1].update(blur_px=-1), ("rig.json", "blur")),
    ("rig", lambda d: d["cameras"][1].update(blur_px=float("nan")), ("rig.json", "blur")),
    ("rig", lambda d: d["cameras"][1].update(blur_px=1e308), ("rig.json", "blur")),
    ("rig", lambda d: d.update(roi={"min": [1, 1, 1], "max": [0, 0, 0]}), ("rig.json", "roi")),
    ("rig", lambda d: d.update(roi={"min": [0, 0, 0], "max": [0, 0, 0]}), ("rig.json", "roi")),
    ("rig", lambda d: d.update(roi=[]), ("rig.json", "roi")),
    ("rig", lambda d: d.update(format="plantreg.recording"), ("rig.json", "format")),
    ("rig", lambda d: d.update(version=2), ("rig.json", "version")),
    ("rig", lambda d: d.update(version=-1), ("rig.json", "version")),
    ("rig", lambda d: d.update(version="1"), ("rig.json", "version")),
    ("rig", lambda d: d["depth"].update(camera="IR"), ("rig.json", "IR")),
    ("rig", lambda d: d["depth"].update(camera="thermal"), None),  # a valid rig; its recording lacks thermal depth? register decides
    ("rig", lambda d: d["depth"].update(scale=1e-300), ("rig.json", "scale")),
    ("rig", lambda d: d["depth"].update(scale=5e-324), ("rig.json", "scale")),
    ("rig", lambda d: d.update(cameras=[d["cameras"][0]] * 300), ("rig.json", "ir")),
    # recording.json
    ("manifest", lambda d: d["images"].update(IR="ir.npy"), ("recording.json", "IR")),
    ("manifest", lambda d: d["images"].update({"th\u00e9rmal": "thermal.tif"}), ("recording.json", "th")),
    ("manifest", lambda d: d["images"].update(thermal=""), ("recording.json", "thermal")),
    ("manifest", lambda d: d["images"].update(thermal="."), ("recording.json", "thermal")),
    ("manifest", lambda d: d["images"].update(thermal="./"), ("recording.json", "thermal")),
    ("manifest", lambda d: d["images"].update(thermal="recording.json"), ("recording.json", "thermal")),
    ("manifest", lambda d: d["images"].update(thermal="depth.png"), ("depth.png", "thermal")),  # one file for two cameras: is it refused or valid?
    ("manifest", lambda d: d["images"].update(rgb="ir.npy"), ("ir.npy", "rgb")),
    ("manifest", lambda d: d.update(depth="thermal.tif"), ("thermal.tif", "depth")),
    ("manifest", lambda d: d.update(depth="/dev/stdin"), ("stdin", "depth")),
    ("manifest", lambda d: d.update(depth="/proc/self/mem"), ("mem", "depth")),
    ("manifest", lambda d: d["images"].update(thermal="/proc/self/environ"), ("environ", "thermal")),
    ("manifest", lambda d: d["images"].update(thermal="~/thermal.tif"), ("thermal.tif", "thermal")),
    ("manifest", lambda d: d["images"].update(thermal="$HOME/thermal.tif"), ("thermal.tif", "thermal")),
    ("manifest", lambda d: d["images"].update(thermal="file:///etc/passwd"), ("passwd", "thermal")),
    ("manifest", lambda d: d["images"].update(thermal="thermal.tif\n"), ("thermal.tif", "thermal")),
    ("manifest", lambda d: d["images"].update(thermal=" thermal.tif"), ("thermal.tif", "thermal")),
    ("manifest", lambda d: d["images"].update(thermal="THERMAL.TIF"), ("THERMAL.TIF", "thermal")),
    ("manifest", lambda d: d["images"].update(thermal="thermal.tif" + "/" * 5000), ("thermal.tif", "thermal")),
    ("manifest", lambda d: d["images"].update(thermal="a/" * 3000 + "t.tif"), ("t.tif", "thermal")),
    ("manifest", lambda d: d.update(images={}), ("recording.json", "images")),
    ("manifest", lambda d: d.update(images=None), ("recording.json", "images")),
    ("manifest", lambda d: d.pop("images"), ("recording.json", "images")),
    ("manifest", lambda d: d.update(format="plantreg.rig"), ("recording.json", "format")),
    ("manifest", lambda d: d.update(depth_scale=True), ("recording.json", "depth_scale")),
    ("manifest", lambda d: d.update(depth_scale=5e-324), ("recording.json", "depth_scale")),
    ("manifest", lambda d: d.update(depth_scale=1001), ("recording.json", "depth_scale")),
    ("manifest", lambda d: d.update(extra={"x": [float("nan")] * 3}), None),
    # session.json
    ("session", lambda d: d["board"].update(columns=True), ("session.json", "columns")),
    ("session", lambda d: d["board"].update(columns=2**70), ("session.json", "columns")),
    ("session", lambda d: d["board"].update(rows=None), ("session.json", "rows")),
    ("session", lambda d: d["board"].update(square_size=5e-324), ("session.json", "square")),
    ("session", lambda d: d["board"].update(square_size=True), ("session.json", "square")),
    ("session", lambda d: d["board"].update(type=None), ("session.json", "type")),
    ("session", lambda d: d["board"].update(type="charuco"), ("session.json", "marker")),
    ("session", lambda d: d["board"].update(type="charuco", marker_size=1.0), ("session.json", "marker")),
    ("session", lambda d: d["board"].update(type="charuco", marker_size=0.03, dictionary="DICT_NOPE"), ("session.json", "dictionary")),
    ("session", lambda d: d.update(format="plantreg.rig"), ("session.json", "format")),
    ("session", lambda d: d.update(version=99), ("session.json", "version")),
    ("session", lambda d: d["cameras"].update(IR=d["cameras"]["ir"]), ("session.json", "IR")),
    ("session", lambda d: d["cameras"].update({"\u00e9": d["cameras"]["ir"]}), ("session.json", "\u00e9")),
    ("session", lambda d: d["cameras"].update({"../x": d["cameras"]["ir"]}), ("session.json", "../x")),
    ("session", lambda d: d["cameras"]["ir"].update(modality=None), ("session.json", "modality")),
    ("session", lambda d: d["cameras"].update(ir="infrared"), ("session.json", "ir")),
    ("session", lambda d: d.update(poses="pose_01"), ("session.json", "poses")),
    ("session", lambda d: d.update(poses=["../../etc"]), ("session.json", "poses")),
    ("session", lambda d: d.update(poses=[]), ("session.json", "poses")),
    ("session", lambda d: d.update(poses=["pose_01", "pose_01"]), ("session.json", "pose_01")),
    ("session", lambda d: d.update(poses=[None]), ("session.json", "poses")),
    ("session", lambda d: d.update(poses=["/etc"]), ("session.json", "poses")),
    ("session", lambda d: d["depth"].update(camera="IR"), ("session.json", "IR")),
    ("session", lambda d: d["depth"].update(scale=-0.001), ("session.json", "scale")),
    ("session", lambda d: d["depth"].update(scale=True), ("session.json", "scale")),
    # landmarks.json
    ("landmarks", lambda d: d["recordings"].update({"/nonexistent/rec": {"points": []}}), ("landmarks.json", "nonexistent")),
    ("landmarks", lambda d: d["recordings"].update({"": next(iter(d["recordings"].values()))}), ("landmarks.json", "recording")),
    ("landmarks", lambda d: d["recordings"].update({"recordings/plant51/": next(iter(d["recordings"].values()))}), ("landmarks.json", "plant51")),
    ("landmarks", lambda d: d["recordings"].update({"recordings/./plant51": next(iter(d["recordings"].values()))}), ("landmarks.json", "plant51")),
    ("landmarks", lambda d: [p.update(depth_uv=[1e9, 1e9]) for v in d["recordings"].values() for p in v["points"]], ("landmarks.json", "depth_uv")),
    ("landmarks", lambda d: [p.update(depth_uv=[True, False]) for v in d["recordings"].values() for p in v["points"]], ("landmarks.json", "depth_uv")),
    ("landmarks", lambda d: [p["cameras"].update(RGB=[1, 1]) for v in d["recordings"].values() for p in v["points"]], ("landmarks.json", "RGB")),
    ("landmarks", lambda d: [p["cameras"].clear() for v in d["recordings"].values() for p in v["points"]], ("landmarks.json", None)),
    ("landmarks", lambda d: [v.update(points=[]) for v in d["recordings"].values()], ("landmarks.json", None)),
    ("landmarks", lambda d: [v.update(points=None) for v in d["recordings"].values()], ("landmarks.json", "points")),
    ("landmarks", lambda d: d.update(format="plantreg.rig"), ("landmarks.json", "format")),
    ("landmarks", lambda d: [p.update(label=None) for v in d["recordings"].values() for p in v["points"]], None),
    ("landmarks", lambda d: [p.update(label="x" * 100000) for v in d["recordings"].values() for p in v["points"]], None),
    ("landmarks", lambda d: [p.update(label=5) for v in d["recordings"].values() for p in v["points"]], ("landmarks.json", "label")),
    # start rig of fit-rig
    ("startrig", lambda d: d["cameras"][1].update(name=d["cameras"][0]["name"]), ("start.json", None)),
    ("startrig", lambda d: d["cameras"][1].update(width=2**64), ("start.json", "width")),
    ("startrig", lambda d: d["cameras"][1].update(dist=[1e6, 0, 0, 0, 0]), ("start.json", "dist")),
]
for i, (fname, fn, word) in enumerate(VALS4):
    def f(r, fname=fname, fn=fn, word=word):
        argv, file = _j(r, fname); _edit(file, fn)
        if word is None:
            return R(argv, None)
        fn_, w = word
        return R(argv, tuple(x for x in (fn_, w) if x))
    f.__name__ = f"val4_{fname}_{i}"; case("ok" if word is None else "refuse")(f)


# ======================================================================= two files, one camera
@case()
def dup_session_and_intrinsics_name_twins(r):
    f = hp._intrinsics_rig(r); _edit(f, lambda d: d["cameras"][0].update(name="IR")); return R(_cal(r, "--intrinsics", f"ir={f}"), None)
@case("ok")
def dup_intrinsics_given_twice_same(r):
    f = hp._intrinsics_rig(r); return R(_cal(r, "--intrinsics", f"ir={f}", f"ir={f}"), None)
@case()
def dup_intrinsics_given_twice_different(r):
    f = hp._intrinsics_rig(r); g = r / "g.json"; shutil.copy(f, g)
    _edit(g, lambda d: d["cameras"][0].update(K=[[310, 0, 159.5], [0, 310, 119.5], [0, 0, 1]]))
    return R(_cal(r, "--intrinsics", f"ir={f}", f"ir={g}"), "ir")
@case()
def dup_batch_same_recording_twice(r):
    rig, rec = mkrec(r); return R(bat(rig, r / "out", rec, rec), "rec")
@case()
def dup_batch_same_recording_two_spellings(r):
    rig, rec = mkrec(r); return R(bat(rig, r / "out", rec, str(rec) + "/."), "rec")
@case()
def dup_batch_symlink_twin(r):
    rig, rec = mkrec(r); os.symlink(rec, r / "rec2"); return R(bat(rig, r / "out", rec, r / "rec2"), "rec")
@case()
def dup_batch_list_and_folder(r):
    rig, rec = mkrec(r); (r / "list.txt").write_text(f"{rec}\n"); return R(bat(rig, r / "out", rec, r / "list.txt"), "rec")
@case()
def dup_fit_recording_given_twice(r):
    rig, rec = mkfit(r); return R(fit(rig, r / "landmarks.json", r / "o.json", "--recording", str(rec), "--recording", str(rec)), None, expect_ok=True)
@case()
def dup_rc_same_file_two_cameras(r):
    _imgs(r); return R(rc(r / "rec", "--image", f"ir={r / 'ir.png'}", "--image", f"rgb={r / 'ir.png'}"), None, expect_ok=True)


# ======================================================================= batch lists
@case()
def list_empty_file(r):
    rig, rec = mkrec(r); (r / "l.txt").write_text(""); return R(bat(rig, r / "out", r / "l.txt"), "l.txt")
@case()
def list_only_comments(r):
    rig, rec = mkrec(r); (r / "l.txt").write_text("# nothing\n\n   \n"); return R(bat(rig, r / "out", r / "l.txt"), "l.txt")
@case()
def list_binary(r):
    rig, rec = mkrec(r); (r / "l.txt").write_bytes(bytes(range(256)) * 10); return R(bat(rig, r / "out", r / "l.txt"), "l.txt")
@case()
def list_utf16(r):
    rig, rec = mkrec(r); (r / "l.txt").write_text(f"{rec}\n", encoding="utf-16"); return R(bat(rig, r / "out", r / "l.txt"), None, expect_ok=True)
@case()
def list_crlf(r):
    rig, rec = mkrec(r); (r / "l.txt").write_bytes(f"{rec}\r\n".encode()); return R(bat(rig, r / "out", r / "l.txt"), None, expect_ok=True)
@case()
def list_huge(r):
    rig, rec = mkrec(r); (r / "l.txt").write_text("/nonexistent/x\n" * 200000); return R(bat(rig, r / "out", r / "l.txt"), "l.txt")
@case()
def list_self_reference(r):
    rig, rec = mkrec(r); (r / "l.txt").write_text(f"{r / 'l.txt'}\n"); return R(bat(rig, r / "out", r / "l.txt"), "l.txt")
@case()
def list_csv_with_header(r):
    rig, rec = mkrec(r); (r / "l.csv").write_text(f"recording,notes\n{rec},x\n"); return R(bat(rig, r / "out", r / "l.csv"), None, expect_ok=True)
@case()
def list_line_is_out(r):
    rig, rec = mkrec(r); (r / "l.txt").write_text(f"{r / 'out'}\n"); (r / "out").mkdir(); return R(bat(rig, r / "out", r / "l.txt"), "out")
@case()
def list_is_dev_stdin(r):
    rig, rec = mkrec(r); return R(bat(rig, r / "out", "/dev/stdin"), "stdin", stdin=f"{rec}\n")
@case()
def batch_csv_is_folder(r):
    rig, rec = mkrec(r); (r / "out" / "batch.csv").mkdir(parents=True); return R(bat(rig, r / "out", rec), "batch.csv")
@case()
def batch_csv_is_fifo(r):
    rig, rec = mkrec(r); (r / "out").mkdir(); os.mkfifo(r / "out" / "batch.csv"); return R(bat(rig, r / "out", rec), "batch.csv", timeout=60)
@case()
def batch_csv_binary(r):
    rig, rec = mkrec(r); (r / "out").mkdir(); (r / "out" / "batch.csv").write_bytes(bytes(range(256)) * 4); return R(bat(rig, r / "out", rec), "batch.csv")
@case()
def batch_csv_huge_field(r):
    rig, rec = mkrec(r); (r / "out").mkdir(); (r / "out" / "batch.csv").write_text("name,status\n" + "x" * 200000 + ",done\n")
    return R(bat(rig, r / "out", rec), None, expect_ok=True)
@case()
def batch_csv_nul(r):
    rig, rec = mkrec(r); (r / "out").mkdir(); (r / "out" / "batch.csv").write_text("name,status\na\x00b,done\n"); return R(bat(rig, r / "out", rec), "batch.csv")
@case()
def batch_csv_symlink_to_rig(r):
    rig, rec = mkrec(r); (r / "out").mkdir(); os.symlink(rig, r / "out" / "batch.csv"); return R(bat(rig, r / "out", rec), "batch.csv")
@case()
def batch_rec_subfolder_is_symlink_to_rec(r):
    rig, rec = mkrec(r); (r / "out").mkdir(); os.symlink(rec, r / "out" / "rec"); return R(bat(rig, r / "out", rec, "--overwrite"), "rec")
@case()
def batch_out_is_symlink_to_recording_parent(r):
    rig, rec = mkrec(r); os.symlink(r, r / "o"); return R(bat(rig, r / "o", rec), None, expect_ok=True)


# ======================================================================= output folders that fill, read-only, other fs
def _tmpfs(r, size="64k"):
    m = r / "mnt"; m.mkdir()
    p = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(m)], capture_output=True)
    if p.returncode:
        raise RuntimeError(f"mount: {p.stderr}")
    return m


def _ro_tmpfs(r):
    m = r / "mnt"; m.mkdir()
    subprocess.run(["mount", "-t", "tmpfs", "-o", "size=1m,ro", "tmpfs", str(m)], check=True)
    return m


@case()
def full_register_out(r):
    rig, rec = mkrec(r); m = _tmpfs(r, "12k"); return R(reg(rig, rec, m / "out"), "out", umount=m)
@case()
def full_register_overwrite_keeps_old(r):
    rig, rec = mkrec(r); m = _tmpfs(r, "40k"); (m / "out").mkdir(); (m / "out" / "old.txt").write_text("old" * 5000)
    return R(reg(rig, rec, m / "out", "--overwrite"), "out", umount=m, keep=[m / "out" / "old.txt"])
@case()
def full_batch(r):
    rig, rec = mkrec(r); m = _tmpfs(r, "16k"); return R(bat(rig, m / "out", rec), "rec", umount=m)
@case()
def full_fit(r):
    rig, rec = mkfit(r); m = _tmpfs(r, "4k"); (m / "fill").write_bytes(b"x" * 4096 if False else b"")
    return R(fit(rig, r / "landmarks.json", m / "o.json"), "o.json", umount=m, fill=m)
@case()
def full_rc(r):
    _imgs(r); m = _tmpfs(r, "4k"); return R(rc(m / "rec", "--image", f"ir={r / 'ir.png'}"), "rec", umount=m, fill=m)
@case()
def full_rig_create(r):
    m = _tmpfs(r, "4k"); return R(hp._rig_create(r).__class__(["rig", "create", str(m / "n.json"), "--depth-camera", "ir", "--camera", "ir=infrared,640x576,f=504,rot=0"]), "n.json", umount=m, fill=m)
@case()
def full_calibrate(r):
    a = _cal(r); m = _tmpfs(r, "4k"); a[a.index("--out") + 1] = str(m / "o.json"); a[a.index("--report") + 1] = str(m / "rep.json")
    return R(a, "o.json", umount=m, fill=m)
@case()
def full_demo(r):
    m = _tmpfs(r, "200k"); return R(["demo", str(m / "d"), "--quiet"], "d", umount=m)
@case()
def ro_fs_register(r):
    rig, rec = mkrec(r); m = _ro_tmpfs(r); return R(reg(rig, rec, m / "out"), "out", umount=m)
@case()
def ro_fs_batch_existing(r):
    rig, rec = mkrec(r); m = _ro_tmpfs(r); return R(bat(rig, m, rec), "mnt", umount=m)
@case("ok")
def other_fs_register_out(r):
    rig, rec = mkrec(r); m = _tmpfs(r, "10m"); return R(reg(rig, rec, m / "out"), None, umount=m)
@case("ok")
def other_fs_register_overwrite_mountpoint_child(r):
    rig, rec = mkrec(r); m = _tmpfs(r, "10m"); (m / "out").mkdir(); (m / "out" / "x").write_text("x")
    return R(reg(rig, rec, m / "out", "--overwrite"), None, umount=m)
@case()
def other_fs_register_overwrite_mountpoint(r):
    rig, rec = mkrec(r); m = _tmpfs(r, "10m"); (m / "x").write_text("x"); return R(reg(rig, rec, m, "--overwrite"), "mnt", umount=m)
@case("ok")
def other_fs_fit_out(r):
    rig, rec = mkfit(r); m = _tmpfs(r, "10m"); return R(fit(rig, r / "landmarks.json", m / "o.json"), None, umount=m)
@case("ok")
def other_fs_rc_images_elsewhere(r):
    _imgs(r); m = _tmpfs(r, "10m"); return R(rc(m / "rec", "--image", f"ir={r / 'ir.png'}", "--depth", str(r / "depth.png")), None, umount=m)
@case()
def fsize_register(r):
    rig, rec = mkrec(r); return R(reg(rig, rec, r / "out"), "out", fsize=2048)
@case()
def fsize_register_overwrite(r):
    rig, rec = mkrec(r); (r / "out").mkdir(); (r / "out" / "old.txt").write_text("old")
    return R(reg(rig, rec, r / "out", "--overwrite"), "out", fsize=2048, keep=[r / "out" / "old.txt"])
@case()
def fsize_calibrate(r):
    return R(_cal(r), "o.json", fsize=1024)
@case()
def fsize_calibrate_overwrite(r):
    a = _cal(r); (r / "o.json").write_text("{}"); (r / "rep.json").write_text("{}")
    return R(a + ["--overwrite"], "json", fsize=1024, keep=[r / "o.json", r / "rep.json"])
@case()
def fsize_fit(r):
    rig, rec = mkfit(r); return R(fit(rig, r / "landmarks.json", r / "o.json"), "o.json", fsize=1024)
@case()
def fsize_batch(r):
    rig, rec = mkrec(r); return R(bat(rig, r / "out", rec), "rec", fsize=2048)
@case()
def fsize_demo(r):
    return R(["demo", str(r / "d"), "--quiet"], "d", fsize=100000)
@case()
def fsize_rc(r):
    _imgs(r); return R(rc(r / "rec", "--image", f"ir={r / 'ir.png'}", "--image", "x" * 60 + f"={r / 'ir.png'}"), "recording.json", fsize=40)
@case()
def fsize_rig_create(r):
    return R(["rig", "create", str(r / "n.json"), "--depth-camera", "ir", "--camera", "ir=infrared,640x576,f=504,rot=0"], "n.json", fsize=100)


# ======================================================================= paths
@case()
def path_leading_dash_out(r):
    rig, rec = mkrec(r); return R(reg(rig, rec, "-out"), None, expect_ok_or_refuse=True, cwd=r)
@case("ok")
def path_leading_dash_out_eq(r):
    rig, rec = mkrec(r); a = reg(rig, rec, "x"); i = a.index("--out"); a[i:i + 2] = ["--out=-out"]; return R(a, None, cwd=r)
@case("ok")
def path_leading_dash_recording(r):
    rig, rec = mkrec(r); shutil.move(rec, r / "-rec"); a = reg(rig, "x", r / "out"); i = a.index("--recording"); a[i:i + 2] = ["--recording=-rec"]
    return R(a, None, cwd=r)
@case("ok")
def path_leading_dash_demo(r):
    return R(["demo", "--quiet", "--", "-d"], None, cwd=r, slow=True)
@case("ok")
def path_leading_dash_rc(r):
    _imgs(r); return R(["recording", "create", "--image", f"ir={r / 'ir.png'}", "--", "-rec"], None, cwd=r)
@case()
def path_deep_nesting_out(r):
    rig, rec = mkrec(r); return R(reg(rig, rec, r / ("a/" * 2100 + "o")), "o")
@case("ok")
def path_deep_nesting_recording(r):
    rig, rec = mkrec(r); d = r / ("a/" * 60); d.mkdir(parents=True); shutil.move(rec, d / "rec"); return R(reg(rig, d / "rec", r / "out"), None)
@case()
def path_out_trailing_slash_nonexistent_parent_file(r):
    rig, rec = mkrec(r); (r / "f").write_text("x"); return R(reg(rig, rec, str(r / "f") + "/out/"), "f")
@case("ok")
def path_out_with_dotdot(r):
    rig, rec = mkrec(r); (r / "a").mkdir(); return R(reg(rig, rec, r / "a" / ".." / "out"), None)
@case()
def path_out_dotdot_is_recording(r):
    rig, rec = mkrec(r); return R(reg(rig, rec, rec / "x" / "..", "--overwrite"), "rec")
@case()
def path_out_is_dev_shm_file(r):
    rig, rec = mkrec(r); return R(reg(rig, rec, "/proc/self/fd/1"), "fd")
@case()
def path_out_is_proc(r):
    rig, rec = mkrec(r); return R(fit(*mkfit(r)[:1], r / "landmarks.json", "/proc/version", "--overwrite"), "version")
@case()
def path_out_newline_only(r):
    rig, rec = mkrec(r); return R(reg(rig, rec, "\n"), None, expect_ok_or_refuse=True, cwd=r)
@case()
def path_out_space_only(r):
    rig, rec = mkrec(r); return R(reg(rig, rec, " "), None, expect_ok_or_refuse=True, cwd=r)
@case()
def path_out_dot_overwrite(r):
    rig, rec = mkrec(r); (r / "cwd").mkdir(); return R(reg(rig, rec, ".", "--overwrite"), ".", cwd=r / "cwd")
@case()
def path_out_dotdot_overwrite(r):
    rig, rec = mkrec(r); (r / "cwd").mkdir(); return R(reg(rig, rec, "..", "--overwrite"), "..", cwd=r / "cwd")
@case()
def path_out_root(r):
    rig, rec = mkrec(r); return R(reg(rig, rec, "/", "--overwrite"), "/")
@case()
def path_demo_root(r):
    return R(["demo", "/", "--overwrite", "--quiet"], "/")
@case()
def path_out_home_overwrite(r):
    rig, rec = mkrec(r); h = r / "home"; h.mkdir(); (h / "precious").write_text("x")
    return R(reg(rig, rec, "~", "--overwrite"), None, env={"HOME": str(h)}, expect_ok_or_refuse=True, keep=[h / "precious"])
@case()
def path_cwd_deleted(r):
    rig, rec = mkrec(r); return R(reg(rig, rec, "out"), None, deleted_cwd=True, expect_ok_or_refuse=True)
@case()
def path_cwd_deleted_demo(r):
    return R(["demo", "d", "--quiet"], None, deleted_cwd=True, expect_ok_or_refuse=True)
@case()
def path_rig_is_recording_json(r):
    rig, rec = mkrec(r); return R(reg(rec / "recording.json", rec, r / "out"), "recording.json")
@case()
def path_landmarks_is_rig(r):
    rig, rec = mkfit(r); return R(fit(rig, rig, r / "o.json"), "start.json")
@case()
def path_session_is_recording(r):
    rig, rec = mkrec(r); return R(["calibrate", str(rec), "--out", str(r / "o.json"), "--report", str(r / "rep.json")], "rec")
@case()
def path_report_equals_out(r):
    a = _cal(r); a[a.index("--report") + 1] = str(r / "o.json"); return R(a, "o.json")
@case()
def path_report_table_is_session_file(r):
    a = _cal(r); a[a.index("--report") + 1] = str(r / "s" / "session.json"); return R(a + ["--overwrite"], "session.json")
@case()
def path_report_inside_session_overwrite(r):
    a = _cal(r); a[a.index("--out") + 1] = str(r / "s" / "pose_01"); return R(a + ["--overwrite"], "pose_01")
@case()
def path_fit_out_is_recording_extra(r):
    rig, rec = mkfit(r); rig2, rec2 = mkrec(r)
    return R(fit(rig, r / "landmarks.json", rec2 / "recording.json", "--overwrite", "--recording", str(rec2)), None, expect_ok_or_refuse=True)
@case()
def path_rig_create_out_is_kinect(r):
    k = r / "k.json"; shutil.copy("/work/main/tests/data/kinect_calibration.json", k) if os.path.exists("/work/main/tests/data/kinect_calibration.json") else k.write_text("{}")
    return R(["rig", "create", str(k), "--overwrite", "--depth-camera", "ir", "--camera", f"ir=infrared,640x576,kinect={k},rot=0"], "k.json")
@case()
def path_rc_dir_is_image_folder_overwrite(r):
    _imgs(r); (r / "recording.json").write_text("{}")
    return R(rc(r, "--image", f"ir={r / 'ir.png'}", "--overwrite"), None, expect_ok_or_refuse=True)
@case()
def path_rc_depth_is_manifest_symlink(r):
    _imgs(r); (r / "rec").mkdir(); os.symlink(r / "depth.png", r / "rec" / "recording.json")
    return R(rc(r / "rec", "--depth", str(r / "depth.png"), "--overwrite"), "recording.json")
@case()
def path_gui_export_out_nonascii(r):
    return R(None, None, skip=True)


# ======================================================================= environment
@case("ok")
def env_home_unset(r):
    rig, rec = mkrec(r); return R(reg(rig, rec, r / "out"), None, env={"HOME": None})
@case("ok")
def env_home_unset_batch(r):
    rig, rec = mkrec(r); return R(bat(rig, r / "out", rec), None, env={"HOME": None})
@case("ok")
def env_home_nonexistent_fit(r):
    rig, rec = mkfit(r); return R(fit(rig, r / "landmarks.json", r / "o.json"), None, env={"HOME": "/nonexistent"})
@case("ok")
def env_lang_c_nonascii_out(r):
    rig, rec = mkrec(r); return R(reg(rig, rec, r / "ausgabe_\u00e4\u00f6"), None, env={"LANG": "C", "LC_ALL": "C"})
@case("ok")
def env_lang_c_nonascii_recording(r):
    rig, rec = mkrec(r); shutil.move(rec, r / "r\u00e9c"); return R(reg(rig, r / "r\u00e9c", r / "out"), None, env={"LANG": "C", "LC_ALL": "C"})
@case()
def env_lang_c_nonascii_missing(r):
    rig, rec = mkrec(r); return R(reg(rig, r / "r\u00e9c_missing", r / "out"), "missing", env={"LANG": "C", "LC_ALL": "C"})
@case("ok")
def env_ascii_stdout_nonascii_out(r):
    rig, rec = mkrec(r); return R(reg(rig, rec, r / "\u00e4out"), None, env={"PYTHONIOENCODING": "ascii"})
@case()
def env_ascii_stderr_nonascii_missing(r):
    rig, rec = mkrec(r); return R(reg(rig, r / "\u00e4missing", r / "out"), "missing", env={"PYTHONIOENCODING": "ascii"})
@case("ok")
def env_ascii_batch_nonascii(r):
    rig, rec = mkrec(r); shutil.move(rec, r / "r\u00e9c"); return R(bat(rig, r / "out", r / "r\u00e9c"), None, env={"PYTHONIOENCODING": "ascii"})
@case()
def env_ascii_batch_failing_nonascii(r):
    rig, rec = mkrec(r); shutil.move(rec, r / "r\u00e9c"); (r / "r\u00e9c" / "thermal.tif").write_bytes(b"")
    return R(bat(rig, r / "out", r / "r\u00e9c"), "thermal.tif", env={"PYTHONIOENCODING": "ascii"})
@case("ok")
def env_latin1_locale_nonascii(r):
    rig, rec = mkrec(r); return R(reg(rig, rec, r / "\u00e4out"), None, env={"LC_ALL": "en_US.ISO-8859-1", "LANG": "en_US.ISO-8859-1"})
@case("ok")
def env_tmpdir_unwritable(r):
    rig, rec = mkrec(r); (r / "ro").mkdir(); os.chmod(r / "ro", 0o555); return R(reg(rig, rec, r / "out"), None, env={"TMPDIR": str(r / "ro")}, nocap=True)
@case("ok")
def env_tmpdir_missing_batch(r):
    rig, rec = mkrec(r); return R(bat(rig, r / "out", rec, "--workers", "2"), None, env={"TMPDIR": "/nonexistent/tmp"})
@case("ok")
def env_tmpdir_file_calibrate(r):
    (r / "tf").write_text("x"); return R(_cal(r), None, env={"TMPDIR": str(r / "tf")}, slow=True)
@case("ok")
def env_tmpdir_missing_demo(r):
    return R(["demo", str(r / "d"), "--quiet"], None, env={"TMPDIR": "/nonexistent/tmp"}, slow=True)
@case("ok")
def env_xdg_cache_unwritable(r):
    rig, rec = mkrec(r); return R(reg(rig, rec, r / "out"), None, env={"XDG_CACHE_HOME": "/proc/nonexistent", "MPLCONFIGDIR": "/proc/x"})
@case("ok")
def env_path_empty(r):
    rig, rec = mkrec(r); return R(reg(rig, rec, r / "out"), None, env={"PATH": ""})
@case("ok")
def env_umask_077(r):
    rig, rec = mkrec(r); return R(reg(rig, rec, r / "out"), None, umask=0o077)
@case("ok")
def env_umask_777(r):
    rig, rec = mkrec(r); return R(reg(rig, rec, r / "out"), None, umask=0o777, expect_ok_or_refuse=True)
@case("ok")
def env_omp_threads_garbage(r):
    rig, rec = mkrec(r); return R(reg(rig, rec, r / "out"), None, env={"OMP_NUM_THREADS": "garbage", "OPENBLAS_NUM_THREADS": "-5"})
@case("ok")
def env_columns_zero(r):
    rig, rec = mkrec(r); return R(bat(rig, r / "out", rec), None, env={"COLUMNS": "0", "TERM": "dumb"})
@case("ok")
def env_nofile_limit_batch(r):
    rig, rec = mkrec(r); return R(bat(rig, r / "out", rec, "--workers", "2"), None, nofile=40, expect_ok_or_refuse=True)
@case()
def env_nofile_limit_tiny(r):
    rig, rec = mkrec(r); return R(reg(rig, rec, r / "out"), None, nofile=12, expect_ok_or_refuse=True)
@case()
def env_nproc_limit_batch(r):
    rig, rec = mkrec(r); return R(bat(rig, r / "out", rec, "--workers", "4"), None, nproc=1, expect_ok_or_refuse=True, nocap=True)
@case()
def env_cpu_limit(r):
    rig, rec = mkrec(r); return R(reg(rig, rec, r / "out"), None, cpu=1, expect_ok_or_refuse=True)
@case()
def env_stack_limit(r):
    rig, rec = mkrec(r); return R(reg(rig, rec, r / "out"), None, stack=256 * 1024, expect_ok_or_refuse=True)
@case()
def env_memory_limit_reading(r):
    rig, rec = mkrec(r); np.save(rec / "ir.npy", np.zeros((H, W), np.uint16))
    _npy_header(rec / "ir.npy", "<f8", (H, W, 4000), data=b"\x00" * (8 * H * W * 4000)); return R(reg(rig, rec, r / "out"), None, aslimit=1500000, expect_ok_or_refuse=True)


# ======================================================================= streams
@case("ok")
def stream_stdin_closed(r):
    rig, rec = mkrec(r); return R(reg(rig, rec, r / "out"), None, close_fds="0")
@case()
def stream_stderr_closed_refusal(r):
    rig, rec = mkrec(r); return R(reg(rig, r / "missing", r / "out"), None, close_fds="2", expect_ok_or_refuse=True)
@case("ok")
def stream_stderr_closed_ok(r):
    rig, rec = mkrec(r); return R(reg(rig, rec, r / "out")[:-1], None, close_fds="2")
@case("ok")
def stream_stderr_closed_batch(r):
    rig, rec = mkrec(r); return R(bat(rig, r / "out", rec)[:-1] if False else ["batch", "--rig", str(rig), "--target", "ir", "--out", str(r / "out"), str(rec)], None, close_fds="2")
@case()
def stream_all_closed(r):
    rig, rec = mkrec(r); return R(reg(rig, rec, r / "out"), None, close_fds="012", expect_ok_or_refuse=True)
@case()
def stream_head_register(r):
    rig, rec = mkrec(r); return R(reg(rig, rec, r / "out"), None, head=True)
@case()
def stream_head_batch(r):
    rig, rec = mkrec(r); rec2 = r / "rec2"; shutil.copytree(rec, rec2); return R(bat(rig, r / "out", rec, rec2), None, head=True)
@case()
def stream_head_calibrate(r):
    return R(_cal(r), None, head=True, slow=True)
@case()
def stream_head_fit(r):
    rig, rec = mkfit(r); return R(fit(rig, r / "landmarks.json", r / "o.json"), None, head=True)
@case()
def stream_head_demo(r):
    return R(["demo", str(r / "d")], None, head=True, slow=True)
@case()
def stream_head_rig_create(r):
    return R(["rig", "create", str(r / "n.json"), "--depth-camera", "ir", "--camera", "ir=infrared,640x576,f=504,rot=0", "--camera", hp.RC_OK], None, head=True)
@case()
def stream_head_help(r):
    return R(["--help"], None, head=True)
@case()
def stream_head_register_help(r):
    return R(["register", "--help"], None, head=True)
@case()
def stream_stderr_pipe_closed(r):
    rig, rec = mkrec(r); return R(reg(rig, rec, r / "out")[:-1], None, stderr_head=True)
@case()
def stream_stdout_devfull_batch(r):
    rig, rec = mkrec(r); return R(bat(rig, r / "out", rec), "standard output", devfull=True)
@case()
def stream_stdout_devfull_help(r):
    return R(["--help"], "standard output", devfull=True, expect_ok_or_refuse=True)
@case()
def stream_stdout_devfull_version(r):
    return R(["--version"], "standard output", devfull=True, expect_ok_or_refuse=True)
@case()
def stream_stdout_closed_help(r):
    return R(["--help"], None, close_fds="1", expect_ok_or_refuse=True)
@case()
def stream_stdout_nonblocking_pipe_full(r):
    rig, rec = mkrec(r); return R(reg(rig, rec, r / "out"), None, slow_reader=True)


# ======================================================================= signals at moments
def _sig_case(name, make, sig, delays, group=False, twice=False):
    for d in delays:
        def f(r, d=d):
            argv, keep = make(r)
            return R(argv, None, signal=(sig, d, group, twice), keep=keep)
        f.__name__ = f"sig_{name}_{signal.Signals(sig).name}_{'grp_' if group else ''}{'twice_' if twice else ''}{d}"
        case("signal")(f)


def _demo_rec(r):
    rig = r / "rig.json"; shutil.copy(f"{ROOT}/demo/rig.json", rig)
    rec = r / "rec"; os.symlink(f"{ROOT}/demo/recording", rec)
    return rig, rec


def _mk_reg_big(r):
    rig, rec = _demo_rec(r); return reg(rig, rec, r / "out"), []


def _mk_reg_big_over(r):
    rig, rec = _demo_rec(r); (r / "out").mkdir(); (r / "out" / "old.txt").write_text("old")
    return reg(rig, rec, r / "out", "--overwrite"), [r / "out" / "old.txt"]


def _mk_batch_big(r):
    rig, rec = _demo_rec(r); recs = []
    for i in range(3):
        os.symlink(f"{ROOT}/demo/recording", r / f"rec{i}"); recs.append(r / f"rec{i}")
    return bat(rig, r / "out", *recs, "--workers", "2"), []


def _mk_cal(r):
    return _cal(r), []


def _mk_cal_over(r):
    a = _cal(r); (r / "o.json").write_text('{"old": 1}'); (r / "rep.json").write_text('{"old": 1}')
    return a + ["--overwrite"], [r / "o.json", r / "rep.json"]


def _mk_fit(r):
    rig, rec = mkfit(r); return fit(rig, r / "landmarks.json", r / "o.json", "--refine"), []


def _mk_demo(r):
    return ["demo", str(r / "d"), "--quiet"], []


def _mk_rc_big(r):
    return rc(r / "newrec", "--depth", f"{ROOT}/demo/recording/depth.png",
              *[x for n in ("rgb", "thermal") for x in ("--image", f"{n}={next(Path(ROOT, 'demo/recording').glob(n + '.*'))}")]), []


SIG_PLAN = [
    ("reg", _mk_reg_big, [0.8, 1.5, 2.5, 4, 6, 9]),
    ("regover", _mk_reg_big_over, [1.5, 4, 7, 10]),
    ("batch", _mk_batch_big, [1.5, 4, 8, 14]),
    ("cal", _mk_cal, [1, 3, 5]),
    ("calover", _mk_cal_over, [2, 4, 6]),
    ("fit", _mk_fit, [1, 3, 6]),
    ("demo", _mk_demo, [2, 10, 25]),
    ("rc", _mk_rc_big, [0.6, 1.2, 2]),
]
for nm, mk, delays in SIG_PLAN:
    _sig_case(nm, mk, signal.SIGINT, delays[::2])
    _sig_case(nm, mk, signal.SIGTERM, delays, group=True)
    _sig_case(nm, mk, signal.SIGHUP, delays[1::2], twice=True)
    _sig_case(nm, mk, signal.SIGTERM, delays[:2], group=True, twice=True)


# ======================================================================= two commands, one folder
def _conc(name, first, second, delay):
    def f(r):
        a1, keep1 = first(r); a2 = second(r)
        return R(a1, None, concurrent=(a2, delay))
    f.__name__ = f"conc_{name}_{delay}"; case("concurrent")(f)


def _c_reg_over(r):
    rig, rec = _demo_rec(r); (r / "out").mkdir(exist_ok=True); (r / "out" / "keep.txt").write_text("x")
    return reg(rig, rec, r / "out", "--overwrite"), []


def _c_fit_into(r):
    rig, rec = mkfit(r); return fit(rig, r / "landmarks.json", r / "out" / "rig.json")


def _c_rc_into(r):
    _imgs(r); return rc(r / "out", "--image", f"ir={r / 'ir.png'}")


def _c_rigcreate_into(r):
    return ["rig", "create", str(r / "out" / "n.json"), "--depth-camera", "ir", "--camera", "ir=infrared,640x576,f=504,rot=0"]


def _c_demo_over(r):
    (r / "out").mkdir(exist_ok=True); (r / "out" / "keep.txt").write_text("x"); return ["demo", str(r / "out"), "--overwrite", "--quiet"], []


def _c_cal_into(r):
    a = _cal(r); a[a.index("--out") + 1] = str(r / "out" / "rig.json"); a[a.index("--report") + 1] = str(r / "out" / "rep.json"); return a


def _c_reg_sub(r):
    rig, rec = mkrec(r); return reg(rig, rec, r / "out" / "sub")


def _c_batch_into(r):
    rig, rec = mkrec(r); return bat(rig, r / "out", rec)


for d in (1.0, 3.0):
    _conc("regover_fit", _c_reg_over, _c_fit_into, d)
    _conc("regover_rc", _c_reg_over, _c_rc_into, d)
    _conc("regover_rigcreate", _c_reg_over, _c_rigcreate_into, d)
    _conc("regover_cal", _c_reg_over, _c_cal_into, d)
    _conc("regover_regsub", _c_reg_over, _c_reg_sub, d)
    _conc("regover_batch", _c_reg_over, _c_batch_into, d)
    _conc("demoover_fit", _c_demo_over, _c_fit_into, d + 3)
    _conc("demoover_regsub", _c_demo_over, _c_reg_sub, d + 3)


# ======================================================================= the GUI's command line
def gui(*a):
    return ["__GUI__", *a]


@case()
def gui_session_missing(r):
    return R(gui("--session", str(r / "nosuch"), "--screenshot", str(r / "s.png")), "nosuch")
@case()
def gui_session_is_file(r):
    (r / "f").write_text("x"); return R(gui("--session", str(r / "f"), "--screenshot", str(r / "s.png")), "f")
@case()
def gui_session_nul(r):
    return R(gui("--session", "a\x00b"), None, expect_ok_or_refuse=True, argv_nul=True)
@case()
def gui_rig_loop(r):
    os.symlink("l", r / "l"); rig, rec = mkrec(r)
    return R(gui("--rig", str(r / "l"), "--recording", str(rec), "--screenshot", str(r / "s.png")), "l")
@case()
def gui_rig_nan(r):
    rig, rec = mkrec(r); _edit(rig, lambda d: d["cameras"][0].update(width=float("nan")))
    return R(gui("--rig", str(rig), "--recording", str(rec), "--screenshot", str(r / "s.png")), "rig.json")
@case()
def gui_recording_fifo(r):
    rig, rec = mkrec(r); os.mkfifo(r / "ff")
    return R(gui("--rig", str(rig), "--recording", str(r / "ff"), "--screenshot", str(r / "s.png")), "ff")
@case()
def gui_screenshot_into_missing_folder(r):
    rig, rec = mkrec(r); return R(gui("--rig", str(rig), "--recording", str(rec), "--screenshot", str(r / "no" / "s.png")), None, expect_ok_or_refuse=True)
@case()
def gui_screenshot_is_rig(r):
    rig, rec = mkrec(r); return R(gui("--rig", str(rig), "--recording", str(rec), "--screenshot", str(rig)), "rig.json")
@case()
def gui_screenshot_is_fifo(r):
    rig, rec = mkrec(r); os.mkfifo(r / "s.png"); return R(gui("--rig", str(rig), "--recording", str(rec), "--screenshot", str(r / "s.png")), "s.png")
@case()
def gui_screenshot_is_folder(r):
    rig, rec = mkrec(r); (r / "s.png").mkdir(); return R(gui("--rig", str(rig), "--recording", str(rec), "--screenshot", str(r / "s.png")), "s.png")
@case()
def gui_screenshot_readonly(r):
    rig, rec = mkrec(r); (r / "ro").mkdir(); os.chmod(r / "ro", 0o555)
    return R(gui("--rig", str(rig), "--recording", str(rec), "--screenshot", str(r / "ro" / "s.png")), "s.png", nocap=True)
@case()
def gui_screenshot_txt_suffix(r):
    rig, rec = mkrec(r); return R(gui("--rig", str(rig), "--recording", str(rec), "--screenshot", str(r / "s.txt")), None, expect_ok_or_refuse=True)
@case()
def gui_screenshot_is_image_input(r):
    rig, rec = mkrec(r); return R(gui("--rig", str(rig), "--recording", str(rec), "--screenshot", str(rec / "rgb.png")), "rgb.png")
@case()
def gui_size_garbage(r):
    return R(gui("--size", "0x0", "--screenshot", str(r / "s.png")), "--size")
@case()
def gui_size_huge(r):
    return R(gui("--size", "100000x100000", "--screenshot", str(r / "s.png")), "--size")
@case()
def gui_size_negative(r):
    return R(gui("--size", "-5x-5", "--screenshot", str(r / "s.png")), "--size")
@case()
def gui_timeout_nan(r):
    return R(gui("--timeout", "nan", "--screenshot", str(r / "s.png")), "--timeout")
@case()
def gui_timeout_neg(r):
    return R(gui("--timeout", "-1", "--screenshot", str(r / "s.png")), "--timeout")
@case()
def gui_page_huge(r):
    return R(gui("--calibrate-demo", "--page", "99", "--screenshot", str(r / "s.png")), "--page")
@case()
def gui_page_zero(r):
    return R(gui("--calibrate-demo", "--page", "0", "--screenshot", str(r / "s.png")), "--page")
@case()
def gui_view_unknown(r):
    rig, rec = mkrec(r); return R(gui("--rig", str(rig), "--recording", str(rec), "--view", "nosuch", "--screenshot", str(r / "s.png")), "nosuch")
@case()
def gui_target_unknown(r):
    rig, rec = mkrec(r); return R(gui("--rig", str(rig), "--recording", str(rec), "--target", "nosuch", "--screenshot", str(r / "s.png")), "nosuch")
@case()
def gui_landmarks_no_rig(r):
    rig, rec = mkfit(r); return R(gui("--landmarks", str(r / "landmarks.json"), "--screenshot", str(r / "s.png")), "--rig")
@case()
def gui_landmarks_binary(r):
    rig, rec = mkfit(r); (r / "landmarks.json").write_bytes(bytes(range(256))); return R(gui("--rig", str(rig), "--landmarks", str(r / "landmarks.json"), "--screenshot", str(r / "s.png")), "landmarks.json")
@case()
def gui_install_desktop_home_readonly(r):
    h = r / "h"; h.mkdir(); os.chmod(h, 0o555); return R(gui("--install-desktop"), "h", env={"HOME": str(h), "XDG_DATA_HOME": None}, nocap=True)
@case()
def gui_install_desktop_xdg_file(r):
    (r / "x").write_text("x"); return R(gui("--install-desktop"), "x", env={"XDG_DATA_HOME": str(r / "x")})
@case()
def gui_install_desktop_xdg_full(r):
    m = _tmpfs(r, "4k"); return R(gui("--install-desktop"), "mnt", env={"XDG_DATA_HOME": str(m)}, umount=m, fill=m)
@case()
def gui_install_desktop_home_unset(r):
    return R(gui("--install-desktop"), None, env={"HOME": None, "XDG_DATA_HOME": str(r / "xdg")}, expect_ok_or_refuse=True)
@case()
def gui_install_desktop_entry_is_folder(r):
    (r / "xdg" / "applications" / "plantreg-gui.desktop").mkdir(parents=True); return R(gui("--install-desktop"), "plantreg-gui.desktop", env={"XDG_DATA_HOME": str(r / "xdg")})
@case()
def gui_uninstall_desktop_entry_fifo(r):
    (r / "xdg" / "applications").mkdir(parents=True); os.mkfifo(r / "xdg" / "applications" / "plantreg-gui.desktop")
    return R(gui("--uninstall-desktop"), None, env={"XDG_DATA_HOME": str(r / "xdg")}, expect_ok_or_refuse=True, timeout=60)


# ======================================================================= runner
def _preexec(run):
    import resource
    def f():
        os.setpgrp() if run.get("signal") and run["signal"][2] else None
        if run.get("fsize") is not None:
            resource.setrlimit(resource.RLIMIT_FSIZE, (run["fsize"], run["fsize"]))
            signal.signal(signal.SIGXFSZ, signal.SIG_DFL)
        if run.get("nofile") is not None:
            resource.setrlimit(resource.RLIMIT_NOFILE, (run["nofile"], run["nofile"]))
        if run.get("nproc") is not None:
            resource.setrlimit(resource.RLIMIT_NPROC, (run["nproc"], run["nproc"]))
        if run.get("cpu") is not None:
            resource.setrlimit(resource.RLIMIT_CPU, (run["cpu"], run["cpu"] + 5))
        if run.get("stack") is not None:
            resource.setrlimit(resource.RLIMIT_STACK, (run["stack"], run["stack"]))
        if run.get("aslimit") is not None:
            resource.setrlimit(resource.RLIMIT_AS, (run["aslimit"] * 1024, run["aslimit"] * 1024))
        if run.get("umask") is not None:
            os.umask(run["umask"])
    return f


def _env(run):
    env = dict(os.environ, PYTHONPATH=SRC)
    for k, v in (run.get("env") or {}).items():
        if v is None:
            env.pop(k, None)
        else:
            env[k] = v
    return env


def _cmd(run):
    argv = run["argv"]
    if argv and argv[0] == "__GUI__":
        return ["xvfb-run", "-a", PY, "-c", "import sys; from plantreg_gui.gui.app import main; sys.exit(main())", *argv[1:]]
    return [PY, "-m", "plantreg_gui", *argv]


def _leftovers(root):
    bad = []
    for dp, dn, fn in os.walk(root):
        for f in fn + dn:
            if re.search(r"\.part|\.old|plantreg-probe|plantreg-lock", f):
                bad.append(os.path.relpath(os.path.join(dp, f), root))
    return bad


def run_case(name, f, expect):
    r = Path(tempfile.mkdtemp(prefix="h4_", dir=f"{ROOT}/runs"))
    os.chmod(r, 0o755)
    run = f(r)
    if run.get("skip"):
        shutil.rmtree(r, ignore_errors=True)
        return "skip", None, ""
    if run.get("expect_ok"):
        expect = "ok"
    cwd = run.get("cwd") or r
    if run.get("deleted_cwd"):
        cwd = r / "gone"; cwd.mkdir()
    before = snapshot(r) if not run.get("umount") else {**snapshot(r)}
    if run.get("fill"):
        m = run["fill"]
        try:
            with open(m / "filler", "wb") as fh:
                while True:
                    fh.write(b"x" * 1024)
        except OSError:
            pass
        before = snapshot(r)
    cmd = _cmd(run)
    if run.get("nocap"):
        cmd = ["setpriv", "--bounding-set=-dac_override,-dac_read_search", *cmd]
    env = _env(run)
    timeout = run.get("timeout", 600)
    t0 = time.monotonic()
    out = err = ""
    rc_ = None
    stdin = subprocess.DEVNULL
    extra_err = ""
    if run.get("stdin") is not None:
        stdin = subprocess.PIPE
    if run.get("close_fds") or run.get("head") or run.get("stderr_head") or run.get("devfull") or run.get("deleted_cwd") or run.get("slow_reader"):
        import shlex
        q = " ".join(map(shlex.quote, cmd))
        redir = ""
        for fd in run.get("close_fds") or "":
            redir += f" {fd}>&-" if fd != "0" else " <&-"
        errf = r.parent / (r.name + ".err")
        if run.get("head"):
            sh = f"set -o pipefail; {q} 2>{shlex.quote(str(errf))} | head -c1 >/dev/null; echo ${{PIPESTATUS[0]}} >{shlex.quote(str(errf))}.rc"
        elif run.get("stderr_head"):
            sh = f"{{ {q} 2>&1 1>/dev/null | head -c1 >/dev/null; }}; echo ${{PIPESTATUS[0]}} >{shlex.quote(str(errf))}.rc"
        elif run.get("devfull"):
            sh = f"{q} >/dev/full 2>{shlex.quote(str(errf))}; echo $? >{shlex.quote(str(errf))}.rc"
        elif run.get("slow_reader"):
            sh = f"{q} 2>{shlex.quote(str(errf))} | (sleep 3; cat >/dev/null); echo ${{PIPESTATUS[0]}} >{shlex.quote(str(errf))}.rc"
        elif run.get("deleted_cwd"):
            sh = f"cd {shlex.quote(str(cwd))} && rmdir {shlex.quote(str(cwd))} && {q} 2>{shlex.quote(str(errf))}; echo $? >{shlex.quote(str(errf))}.rc"
        else:
            sh = f"{q}{redir} 2>>{shlex.quote(str(errf))}; echo $? >{shlex.quote(str(errf))}.rc" if "2" not in (run.get("close_fds") or "") else f"{q}{redir}; echo $? >{shlex.quote(str(errf))}.rc"
        p = subprocess.run(["bash", "-c", sh], cwd=r, env=env, timeout=timeout, preexec_fn=_preexec(run), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, errors="surrogateescape")
        err = errf.read_text(errors="surrogateescape") if errf.exists() else ""
        rc_ = int(Path(str(errf) + ".rc").read_text().strip() or -99)
        extra_err = p.stderr
        for x in (errf, Path(str(errf) + ".rc")):
            x.unlink(missing_ok=True)
    elif run.get("signal"):
        sig, delay, group, twice = run["signal"]
        p = subprocess.Popen(cmd, cwd=cwd, env=env, stdin=stdin, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                             text=True, errors="surrogateescape", start_new_session=True)
        time.sleep(delay)
        finished_before = p.poll() is not None
        try:
            if group:
                os.killpg(p.pid, sig)
            else:
                os.kill(p.pid, sig)
            if twice:
                time.sleep(0.05)
                (os.killpg if group else os.kill)(p.pid, sig)
        except ProcessLookupError:
            pass
        try:
            out, err = p.communicate(timeout=120)
        except subprocess.TimeoutExpired:
            os.killpg(p.pid, signal.SIGKILL); out, err = p.communicate(); err += "\nPROBE: HUNG after the signal"
        rc_ = p.returncode
        time.sleep(0.5)  # children finishing their clean-up
        try:
            os.killpg(p.pid, 0); err += "\nPROBE: processes of the group still alive"
            time.sleep(6)
            try:
                os.killpg(p.pid, 0); os.killpg(p.pid, signal.SIGKILL)
            except ProcessLookupError:
                err = err.replace("\nPROBE: processes of the group still alive", "")
        except ProcessLookupError:
            pass
        run["_finished_before"] = finished_before
    elif run.get("concurrent"):
        a2, delay = run["concurrent"]
        p = subprocess.Popen(cmd, cwd=cwd, env=env, stdin=stdin, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        time.sleep(delay)
        p2 = subprocess.run([PY, "-m", "plantreg_gui", *a2], cwd=cwd, env=env, stdin=stdin, capture_output=True, text=True, timeout=timeout)
        out, err = p.communicate(timeout=timeout)
        rc_ = p.returncode
        run["_second"] = (p2.returncode, p2.stdout, p2.stderr, a2)
    else:
        p = subprocess.run(cmd, cwd=cwd, env=env, input=run.get("stdin"), stdin=None if run.get("stdin") is not None else stdin,
                           stdout=subprocess.PIPE if not run.get("devnull_out") else subprocess.DEVNULL,
                           stderr=subprocess.PIPE, text=True, errors="surrogateescape", timeout=timeout, preexec_fn=_preexec(run))
        out, err, rc_ = p.stdout or "", p.stderr, p.returncode
    after = snapshot(r)
    changed = [k for k in before if after.get(k) != before[k] and "/out/" not in k and not k.endswith("/filler")]
    problems = []
    alltext = (err or "") + (out or "") + extra_err
    if "Traceback" in alltext or "Exception ignored" in alltext or "core dumped" in alltext or "PROBE:" in alltext:
        problems.append("traceback/hang/left processes")
    if run.get("no_file") and list(r.rglob(run["no_file"])):
        problems.append(f"{run['no_file']} created (code executed)")
    for k in run.get("keep") or []:
        if not Path(k).exists():
            problems.append(f"lost {k.name}")
    left = _leftovers(r)
    if run.get("umount"):
        subprocess.run(["umount", "-l", str(run["umount"])], capture_output=True)
    verdict = None
    if expect == "signal":
        sig = run["signal"][0]
        if left:
            problems.append(f"leftovers {left}")
        if rc_ not in (0, 128 + sig, 1) and not (rc_ == -sig):
            problems.append(f"rc {rc_}")
        if rc_ == 1 and "terminated" not in err and "interrupted" not in err:
            problems.append("rc 1 on a signal")
        if rc_ == 128 + sig or rc_ == 130:
            outs = [p for p in ("out", "o.json", "d", "newrec/recording.json") if (r / p).exists()]
            if outs and "regover" not in name and "calover" not in name and "batch" not in name:
                problems.append(f"output {outs} stays after a signal exit")
            if "calover" in name and (r / "o.json").exists() and (r / "rep.json").exists():
                a, b = json.loads((r / "o.json").read_text()), json.loads((r / "rep.json").read_text())
                if ("old" in a) != ("old" in b):
                    problems.append("calibrate: a mix of old and new outputs")
        verdict = "MISHANDLED" if problems else "clean"
    elif expect == "concurrent":
        rc2, out2, err2, a2 = run["_second"]
        if "Traceback" in err2:
            problems.append("second: traceback")
        if left:
            problems.append(f"leftovers {left}")
        # both exit 0: both outputs must be there and complete
        sec_out = [a2[a2.index("--out") + 1]] if "--out" in a2 else [a2[2] if a2[0] == "rig" else (a2[2] + "/recording.json" if a2[0] == "recording" else a2[1])]
        if rc2 == 0 and not all(os.path.exists(x) for x in sec_out):
            problems.append(f"second exit 0 but its output {sec_out} is gone (data loss)")
        if rc_ == 0 and not (r / "out" / "summary.json").exists() and not (r / "out" / "rig.json").exists():
            problems.append("first exit 0 but its output is incomplete")
        if rc_ != 0 and rc2 != 0:
            problems.append(f"both refused ({rc_}, {rc2}): {err.strip()[-150:]} | {err2.strip()[-150:]}")
        verdict = "MISHANDLED" if problems else "clean"
        err = f"[1] rc={rc_} {err.strip()[-200:]} [2] rc={rc2} {err2.strip()[-200:]}"
    elif expect == "ok" or run.get("expect_ok_or_refuse") and rc_ == 0:
        if rc_ != 0:
            problems.append(f"rc {rc_}")
        if left:
            problems.append(f"leftovers {left}")
        verdict = "MISHANDLED" if problems else "ok"
        if rc_ != 0 and not [x for x in problems if x.startswith("trace")] and expect != "ok":
            verdict = "MISHANDLED"
        if rc_ != 0 and expect == "ok" and not [x for x in problems if x.startswith("trace")]:
            verdict = "REFUSED-OK?"  # a valid input refused: judged by hand
    else:
        if run.get("head") or run.get("stderr_head"):
            if rc_ not in (0, 141, 1):
                problems.append(f"rc {rc_}")
            if left:
                problems.append(f"leftovers {left}")
            verdict = "MISHANDLED" if problems else "clean"
        else:
            if rc_ == 0:
                problems.append("exit 0")
            if rc_ is not None and rc_ < 0 or rc_ in (-9, 137, 139, 134):
                problems.append(f"killed rc {rc_}")
            if changed:
                problems.append(f"inputs changed {[os.path.relpath(c, r) for c in changed][:4]}")
            if left:
                problems.append(f"leftovers {left}")
            lines = [l for l in err.strip().splitlines() if l.strip() and not l.startswith("[") and not l.startswith("QStandardPaths") and "xvfb" not in l.lower()]
            verdict = "MISHANDLED" if problems else "clean"
            if not problems:
                words = run["culprit"] if isinstance(run["culprit"], tuple) else (run["culprit"],)
                need = [str(w) for w in words if w is not None]
                miss = [w for w in need if w not in err and Path(w).name not in err]
                if rc_ == 2 and len(lines) >= 2 and lines[0].startswith("usage:") and ": error: " in lines[-1]:
                    lines = lines[-1:]
                if run["argv"] and run["argv"][0] == "batch":
                    lines = [l for l in (err + out).strip().splitlines() if l.strip() and not re.match(r"\d+ recording\(s\): ", l) and not l.startswith("[") and not l.startswith("plantreg batch:")]
                    lines = lines[:1] if lines and all("failed" in l or "error" in l for l in lines) else lines
                    miss = [w for w in need if w not in err + out and Path(w).name not in err + out]
                if len(lines) != 1 or miss or ".part" in err or "XXXX" in err:
                    verdict = "VAGUE"
    shutil.rmtree(r, ignore_errors=True)
    if os.path.exists(r):
        subprocess.run(["chmod", "-R", "u+w", str(r)]); shutil.rmtree(r, ignore_errors=True)
    return verdict, rc_, (problems, (err or "").strip()[-400:])


if __name__ == "__main__":
    Path(ROOT, "runs").mkdir(parents=True, exist_ok=True)
    hp._fixtures()
    if not Path(ROOT, "demo").exists():
        subprocess.run([PY, "-m", "plantreg_gui", "demo", f"{ROOT}/demo", "--quiet"], check=True, env=dict(os.environ, PYTHONPATH=SRC))
    hp.run_cases(CASES, run_case, only, width=48, error_chars=300)
