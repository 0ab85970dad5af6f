"""Reading images of every modality, and writing files atomically.

Readers keep values as they are: float thermal stays float, 16-bit stays 16-bit, a 204-band
cube stays 204 bands. Arrays are (H, W) or (H, W, C), band-last. Colour images read with
OpenCV are returned as RGB (not OpenCV's BGR).

Hostile files are refused before anything large is allocated (``docs/errors.md``): every reader
first checks that the path is a readable regular file, then reads the format's header and
compares the size it claims with :data:`MAX_PIXELS`, :data:`MAX_BANDS`, :data:`MAX_IMAGE_BYTES`
and, for uncompressed formats, with the file's size. Values must be real numbers (complex,
structured and object arrays are refused with the reason). Truncated PNG/JPEG files are
refused as such instead of being decoded with grey fill.

Length: one reader per image format, each with its header checks before any allocation, and
the atomic writes every command uses.
"""

from __future__ import annotations

import errno
import os
import shutil
import warnings
from contextlib import contextmanager
from pathlib import Path
from typing import Callable, Iterator

import cv2
import numpy as np

from ..errors import InputError, one_line
from .. import signals
from .paths import check_destination, check_input_file, check_output_location, temp_beside  # noqa: F401 (the writers' and readers' checks; check_output_location is imported from here too)

#: Still formats OpenCV decodes besides PNG/JPEG/TIFF (thermal and machine-vision cameras write
#: 16-bit PGM, 8-bit PPM, BMP): suffix -> (format name, accepted file signatures).
_NETPBM = ("P1", "P2", "P3", "P4", "P5", "P6")
OPENCV_STILLS = {
    ".pgm": ("PGM", _NETPBM), ".ppm": ("PPM", _NETPBM), ".pbm": ("PBM", _NETPBM), ".pnm": ("PNM", _NETPBM),
    ".pxm": ("PNM", _NETPBM), ".pfm": ("PFM", ("Pf", "PF")),
    ".bmp": ("BMP", ("BM",)), ".dib": ("BMP", ("BM",)),
    ".webp": ("WebP", ("RIFF",)), ".jp2": ("JPEG 2000", ("\x00\x00\x00\x0cjP",)),
    ".sr": ("Sun raster", ("\x59\xa6\x6a\x95",)), ".ras": ("Sun raster", ("\x59\xa6\x6a\x95",)),
}
IMAGE_SUFFIXES = (".npy", ".png", ".jpg", ".jpeg", ".tif", ".tiff", ".hdr", *OPENCV_STILLS)

#: Sanity bounds of an input image (documented in docs/errors.md). A 4K RGB image has 8.3 M
#: pixels and the paper's hyperspectral cube 512 x 512 x 204 values; the bounds are far above
#: any real camera and far below what a forged header can claim (terabytes).
MAX_PIXELS = 1 << 28  # width x height (e.g. 16384 x 16384)
MAX_SIDE = 1 << 16  # width or height
MAX_BANDS = 4096
MAX_IMAGE_BYTES = 1 << 32  # 4 GiB for the decoded array
#: JSON inputs (rig, recording, session) are a few kB; anything much larger is not one of them.
MAX_JSON_BYTES = 64 << 20

#: dtype kinds an image may have: booleans, integers, floats (real numbers).
_REAL_KINDS = "biuf"


def _check_array_header(path: Path, shape: tuple[int, ...], dtype: np.dtype, what: str = "header") -> None:
    """Refuse a claimed array shape/dtype that is not a sane real-valued image (before reading it)."""
    dtype = np.dtype(dtype)
    if dtype.names is not None or dtype.kind == "V":
        raise InputError(f"structured dtype {dtype} (fields {', '.join(dtype.names or ())}); an image holds "
                         "plain numbers: save one field per file", path)
    if dtype.kind == "c":
        raise InputError(f"complex values (dtype {dtype}); plantreg reads real numbers: save the magnitude "
                         "or the real part", path)
    if dtype.kind not in _REAL_KINDS:
        raise InputError(f"dtype {dtype} is not numeric (an image holds integers or floats)", path)
    shape = tuple(int(s) for s in shape)
    if len(shape) == 3 and shape[2] == 1:
        shape = shape[:2]
    if len(shape) not in (2, 3):
        raise InputError(f"not an image: {what} claims shape {shape} (expected H x W or H x W x C)", path)
    if min(shape) <= 0:
        raise InputError(f"empty image: {what} claims shape {shape}", path)
    h, w = shape[:2]
    bands = shape[2] if len(shape) == 3 else 1
    nbytes = h * w * bands * dtype.itemsize
    if h > MAX_SIDE or w > MAX_SIDE or h * w > MAX_PIXELS or bands > MAX_BANDS or nbytes > MAX_IMAGE_BYTES:
        raise InputError(
            f"{what} claims {w} x {h} pixels x {bands} band(s) of {dtype} ({_human(nbytes)}), beyond plantreg's "
            f"sanity bound ({MAX_SIDE} pixels a side, {MAX_PIXELS >> 20} M pixels, {MAX_BANDS} bands, "
            f"{_human(MAX_IMAGE_BYTES)}); a corrupt or forged header?", path)


def _check_data_size(path: Path, data_file: Path, offset: int, nbytes: int, what: str) -> None:
    size = data_file.stat().st_size
    if size < offset + nbytes:
        where = "" if data_file == path else f" ({data_file.name})"
        raise InputError(f"truncated: the {what} claims {_human(nbytes)} of pixel data but the file{where} holds "
                         f"{_human(max(size - offset, 0))}", path)


def _human(n: int) -> str:
    for unit in ("bytes", "KiB", "MiB", "GiB", "TiB", "PiB"):
        if n < 1024 or unit == "PiB":
            return f"{n} {unit}" if unit == "bytes" else f"{n:.1f} {unit}"
        n /= 1024
    return str(n)  # pragma: no cover


def _read_npy(path: Path) -> Callable[[], np.ndarray]:
    from numpy.lib import format as npf

    with open(path, "rb") as f:
        try:
            version = npf.read_magic(f)
            if version == (1, 0):
                shape, _fortran, dtype = npf.read_array_header_1_0(f)
            elif version == (2, 0):
                shape, _fortran, dtype = npf.read_array_header_2_0(f)
            elif version == (3, 0):  # 2.0 with a UTF-8 header; no public reader
                impl = getattr(np.lib, "_format_impl", npf)
                shape, _fortran, dtype = impl._read_array_header(f, version)
            else:
                raise ValueError(f"unsupported .npy format version {version[0]}.{version[1]}")
        except ValueError as e:
            raise InputError(f"not a valid .npy file ({one_line(str(e))})", path) from None
        offset = f.tell()
    if dtype.hasobject:
        raise InputError(f"dtype {dtype} holds Python objects (pickles are never loaded); an image holds numbers",
                         path)
    _check_array_header(path, shape, dtype, "the .npy header")
    _check_data_size(path, path, offset, int(np.prod(shape)) * dtype.itemsize, ".npy header")
    return lambda: np.load(path, allow_pickle=False)


def _pillow_header(path: Path, kind: str, verify: bool = False) -> tuple[int, int, int, str, dict]:
    """An image file's header read by Pillow without decoding the pixels (decompression bombs
    are refused before any decoding): (width, height, bands, Pillow mode, info). ``verify``:
    also check the file's structure (PNG chunk CRCs). A bad header raises :class:`InputError`
    naming the file as a ``kind`` file."""
    from PIL import Image

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            with Image.open(path) as im:
                out = (*im.size, len(im.getbands()), im.mode, dict(im.info))
                if verify:
                    im.verify()
    except Image.DecompressionBombError as e:
        raise InputError(f"{kind} header claims an image beyond plantreg's sanity bound ({one_line(str(e))})",
                         path) from None
    except (OSError, SyntaxError, ValueError) as e:
        raise InputError(f"corrupt or truncated {kind} file ({one_line(str(e))})", path) from None
    return out


def _read_png_jpeg(path: Path, suffix: str) -> Callable[[], np.ndarray]:
    with open(path, "rb") as f:
        head = f.read(33)  # signature, then a PNG's IHDR chunk
        f.seek(0, os.SEEK_END)
        size = f.tell()
        f.seek(max(size - 4096, 0))
        tail = f.read()
    is_png, is_jpeg = head.startswith(b"\x89PNG\r\n\x1a\n"), head.startswith(b"\xff\xd8")
    if not (is_png or is_jpeg):
        raise InputError(f"not a {'PNG' if suffix == '.png' else 'JPEG'} file (its first bytes are not the "
                         "format's signature)", path)
    kind = "PNG" if is_png else "JPEG"
    w, h, bands, mode, info = _pillow_header(path, kind, verify=is_png)  # PNG: chunk CRCs and structure too
    bits = 16 if mode.startswith("I") else 8
    plain = is_png and "transparency" not in info
    _check_array_header(path, (h, w, bands), np.uint16 if bits == 16 else np.uint8, f"the {kind} header")
    # libjpeg decodes a truncated file with grey fill and only a warning: the end marker tells
    if is_jpeg and b"\xff\xd9" not in tail:
        raise InputError("corrupt or truncated JPEG file (no end-of-image marker)", path)
    if is_png and b"IEND" not in tail[-12:]:
        raise InputError("corrupt or truncated PNG file (no IEND chunk at its end)", path)

    # 8/16-bit grey, RGB or RGBA without a tRNS chunk: decoded by libpng through imagecodecs,
    # ~20 % faster than OpenCV for a 4K RGB image and already RGB (no BGR swap); the same values
    # (OpenCV's libpng returns exactly these for these colour types; others go through OpenCV)
    plain = plain and len(head) >= 26 and head[24] in (8, 16) and head[25] in (0, 2, 6)

    def decode() -> np.ndarray:
        if plain:
            try:
                import imagecodecs

                return imagecodecs.png_decode(path.read_bytes())
            except MemoryError:
                raise
            except Exception:  # noqa: BLE001 - no imagecodecs, or a bad file: said below
                pass
        if is_png:  # libpng inside OpenCV prints "libpng error: ..." on stderr for bad data: Pillow says it first
            _pillow_pixels_check(path, kind)
        return _opencv_decode(path, kind)
    return decode


def _pillow_pixels_check(path: Path, kind: str) -> None:
    """Decode the file with Pillow (raising, never printing) and refuse it if its pixel data are
    short or corrupt."""
    from PIL import Image

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            with Image.open(path) as im:
                im.load()
    except Image.DecompressionBombError as e:
        raise InputError(f"{kind} file claims an image beyond plantreg's sanity bound ({one_line(str(e))})",
                         path) from None
    except (OSError, SyntaxError, ValueError, EOFError) as e:
        raise InputError(f"corrupt or truncated {kind} file ({one_line(str(e))})", path) from None


def _opencv_decode(path: Path, kind: str) -> np.ndarray:
    """``cv2.imread`` unchanged, colour as RGB(A); a file it cannot decode is named as corrupt."""
    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise InputError(f"corrupt or truncated {kind} file (OpenCV cannot decode it)", path)
    if img.ndim == 3 and img.shape[2] == 3:
        img = cv2.cvtColor(img, cv2.COLOR_BGR2RGB)
    elif img.ndim == 3 and img.shape[2] == 4:
        img = cv2.cvtColor(img, cv2.COLOR_BGRA2RGBA)
    return img


def _read_opencv_still(path: Path, suffix: str) -> Callable[[], np.ndarray]:
    """PGM/PPM/PBM/PNM/PFM (8- and 16-bit, float), BMP, WebP, JPEG 2000, Sun raster: the signature
    and the header (Pillow, without decoding) are checked first, then OpenCV decodes the pixels."""
    kind, signatures = OPENCV_STILLS[suffix]
    with open(path, "rb") as f:
        head = f.read(16)
    if not any(head.startswith(sig.encode("latin-1")) for sig in signatures) or (
            kind == "WebP" and head[8:12] != b"WEBP"):
        raise InputError(f"not a {kind} file (its first bytes are not the format's signature)", path)
    w, h, bands, mode, _info = _pillow_header(path, kind)
    dtype = {"I": np.uint16, "I;16": np.uint16, "I;16B": np.uint16, "F": np.float32}.get(mode, np.uint8)
    _check_array_header(path, (h, w, bands), dtype, f"the {kind} header")
    if head[:2] in (b"P4", b"P5", b"P6", b"Pf", b"PF"):  # binary netpbm: the pixel data must all be there
        per = {b"P4": 0, b"P5": 1, b"P6": 3, b"Pf": 1, b"PF": 3}[head[:2]]
        item = 4 if head[:2] in (b"Pf", b"PF") else np.dtype(dtype).itemsize
        nbytes = (w + 7) // 8 * h if per == 0 else w * h * per * item
        if path.stat().st_size < nbytes + 7:  # the shortest header: "P5 1 1 1\n" minus the digits
            raise InputError(f"truncated {kind} file: the header claims {w} x {h} pixels ({_human(nbytes)}) but "
                             f"the file holds {_human(path.stat().st_size)}", path)
    if head[:2] == b"BM" and int.from_bytes(head[2:6], "little") > path.stat().st_size:
        raise InputError(f"truncated BMP file: its header says {int.from_bytes(head[2:6], 'little')} bytes but the "
                         f"file holds {path.stat().st_size}", path)

    def decode() -> np.ndarray:
        return _opencv_decode(path, kind)
    return decode


def _read_tiff(path: Path) -> Callable[[], np.ndarray]:
    import tifffile

    with tifffile.TiffFile(path) as tf:  # closed here: a decoder that never runs holds no file
        if not tf.series:
            raise InputError("TIFF file holds no image", path)
        series = tf.series[0]
        shape, axes = tuple(series.shape), series.axes
        # a stack of one page (numpy's (1, H, W) written as it is): the page, not a 1-row image
        squeeze = len(shape) >= 3 and shape[0] == 1 and axes[:1] not in ("S", "Y")
        if squeeze:
            shape, axes = shape[1:], axes[1:]
        # band-first planar cubes are moved band-last below: check the shape they will have
        check = shape[1:] + shape[:1] if len(shape) == 3 and axes.endswith("SYX") else shape
        _check_array_header(path, check, series.dtype, "the TIFF header")
        pages = [p for p in series.pages if p is not None]
        if pages and all(getattr(p, "compression", 1) == 1 for p in pages):
            ends = [max((o + n for o, n in zip(p.dataoffsets, p.databytecounts)), default=0) for p in pages]
            if ends and max(ends) > path.stat().st_size:
                raise InputError("truncated TIFF file: its pixel data would end at byte "
                                 f"{max(ends)} but the file has {path.stat().st_size} bytes", path)

    def decode() -> np.ndarray:
        with tifffile.TiffFile(path) as t:
            img = t.series[0].asarray()
        if squeeze:
            img = img[0]
        if img.ndim == 3 and axes.endswith("SYX"):
            # planar-separate multi-band TIFF (GDAL's INTERLEAVE=BAND): tifffile gives bands
            # first; plantreg's arrays are band-last
            img = np.moveaxis(img, 0, -1)
        return img
    return decode


def _read_envi(path: Path) -> Callable[[], np.ndarray]:
    import spectral.io.envi as envi

    try:
        h = envi.read_envi_header(str(path))
        envi.check_compatibility(h)
        p = envi.gen_params(h)
    except Exception as e:  # spectral raises its own kinds for every header problem
        raise InputError(f"not a valid ENVI header ({type(e).__name__}: {one_line(str(e))})", path) from None
    inter = str(h.get("interleave", "bsq")).lower()
    shape = (p.nrows, p.ncols, p.nbands)
    _check_array_header(path, shape, np.dtype(p.dtype), "the ENVI header")
    # the data file beside the header, found the way spectral does it; checked here so that a
    # missing or unreadable one is named (spectral would leave a half-made object behind)
    stem = path.with_suffix("")
    exts = [""] + [e.lower() for e in envi.KNOWN_EXTS] + [inter]
    exts += [e.upper() for e in exts if e]
    candidates = [Path(f"{stem}.{e}" if e else str(stem)) for e in exts]
    # a folder of that name (a sibling "hyperspectral/" beside "hyperspectral.hdr") is not a data file
    data = next((c for c in candidates if os.path.lexists(c) and not c.is_dir()), None)
    if data is None:
        raise InputError(f"ENVI data file not found beside the header ({stem.name}.img, .dat, .raw, ...)", path)
    check_input_file(data, "ENVI data file")
    _check_data_size(path, data, p.offset, p.nrows * p.ncols * p.nbands * np.dtype(p.dtype).itemsize,
                     "ENVI header")

    def decode() -> np.ndarray:
        mapped = _map_envi(h, p, inter, data)
        if mapped is not None:
            return mapped
        spy = envi.open(str(path), str(data))
        try:
            return np.asarray(spy.load())
        finally:
            del spy
    decode.pixel_file = data  # what the decoder reads: the data file, not the header
    return decode


def _map_envi(h: dict, p, inter: str, data: Path) -> np.ndarray | None:
    """The ENVI cube as spectral's ``load()`` returns it -- same values, dtype and memory layout
    (a band-last view of the file's interleave: BSQ gives an (H, W, C) view of (C, H, W)) -- but
    read with one ``np.fromfile`` instead of through three copies (~1.2 s of CPU for the paper's
    214 MB cube). Not memory-mapped: a map would save ~0.1 s more, but a cube file truncated in
    place while the desktop app holds the recording would end the process (SIGBUS) and lose the
    user's unsaved work. None where spectral would transform the values (a reflectance scale
    factor, frame offsets) or the interleave is unknown: the caller reads it with spectral then."""
    scale = h.get("reflectance scale factor")
    if scale is not None and float(scale) != 1.0:
        return None
    if any(h.get(k) not in (None, "0", 0) and np.any(np.asarray(h.get(k), dtype=float) != 0)
           for k in ("major frame offsets", "minor frame offsets")):
        return None
    dims = {"bsq": (p.nbands, p.nrows, p.ncols), "bil": (p.nrows, p.nbands, p.ncols), "bip": (p.nrows, p.ncols, p.nbands)}
    if inter not in dims:
        return None
    dtype = np.dtype(p.dtype)
    shape = dims[inter]
    a = np.fromfile(data, dtype=dtype, count=int(np.prod(shape)), offset=p.offset)
    if a.size != int(np.prod(shape)):  # the header checks run first; a file shrinking since then
        raise InputError(f"ENVI data file is shorter than its header says ({a.size} of {int(np.prod(shape))} values)",
                         data)
    a = a.reshape(shape)
    a = {"bsq": lambda x: x.transpose(1, 2, 0), "bil": lambda x: x.transpose(0, 2, 1), "bip": lambda x: x}[inter](a)
    if dtype.kind != "c" and dtype.name != "float32":  # spectral converts real data to float32
        a = a.astype(np.float32)
    return a


def read_image(path: str | Path) -> np.ndarray:
    """Read ``.npy``, ``.png``, ``.jpg``, ``.tif``/``.tiff``, an ENVI ``.hdr`` cube, or another
    still format OpenCV decodes (:data:`OPENCV_STILLS`: PGM/PPM/PBM/PNM/PFM 8- and 16-bit, BMP,
    WebP, JPEG 2000, Sun raster).

    Returns (H, W) or (H, W, C) in the file's dtype (real numbers). Raises :class:`InputError`
    naming the file when it is missing, not a regular readable file, corrupt or truncated, not an
    image, or claims a size beyond the sanity bounds (checked from the header, before reading).
    """
    return image_decoder(path)()


def image_decoder(path: str | Path) -> Callable[[], np.ndarray]:
    """:func:`read_image` in two steps: this call checks the file and its header (Python work,
    quick) and returns a function that decodes the pixels (the long part, in OpenCV, numpy or
    imagecodecs with the GIL released) -- so that several images decode in parallel threads
    (:func:`~plantreg_gui.core.data.recording.read_images`). Both steps raise :class:`InputError`.
    The function's ``pixel_file`` is the file it reads (an ENVI header's data file)."""
    path = check_input_file(path, "image")
    if path.stat().st_size == 0:
        try:  # /proc and /sys files say 0 bytes and still have content: not "empty"
            with open(path, "rb") as f:
                content = bool(f.read(1))
        except OSError as e:  # /proc/self/mem
            raise InputError(f"is not an image file on disk: it reports a size of 0 bytes and cannot be read "
                             f"({e.strerror or e})", path) from None
        if content:
            raise InputError("is not an image file on disk: it reports a size of 0 bytes but has content "
                             "(a /proc or /sys pseudo-file?)", path)
        raise InputError("image file is empty (0 bytes)", path)
    suffix = path.suffix.lower()

    def header():
        if suffix == ".npy":
            return _read_npy(path)
        if suffix in (".png", ".jpg", ".jpeg"):
            return _read_png_jpeg(path, suffix)
        if suffix in (".tif", ".tiff"):
            return _read_tiff(path)
        if suffix == ".hdr":
            return _read_envi(path)
        if suffix in OPENCV_STILLS:
            return _read_opencv_still(path, suffix)
        raise InputError(f"unsupported image type '{suffix}' (plantreg reads {', '.join(IMAGE_SUFFIXES)})", path)

    decode = _image_errors(path, header)

    def checked() -> np.ndarray:
        return _checked_image(path, _image_errors(path, decode))
    checked.pixel_file = getattr(decode, "pixel_file", path)  # the file the decoder reads (its size: the work)
    return checked


def _image_errors(path: Path, step: Callable):
    """``step()``, with the libraries' many kinds of errors as one :class:`InputError` naming ``path``."""
    try:
        return step()
    except InputError:
        raise
    except MemoryError:
        raise InputError("not enough memory to read this image", path) from None
    except PermissionError:
        raise InputError("image is not readable (permission denied)", path) from None
    except Exception as e:  # the libraries raise many kinds; the user needs the file and the reason
        raise InputError(f"cannot read image ({type(e).__name__}: {one_line(str(e))})", path) from None


def _checked_image(path: Path, img) -> np.ndarray:
    """The decoded array, refused unless it is an (H, W) or (H, W, C) image of real numbers."""
    img = np.asarray(img)
    if img.ndim == 3 and img.shape[2] == 1:
        img = img[:, :, 0]
    if img.ndim not in (2, 3) or img.size == 0:
        raise InputError(f"not an image: array of shape {img.shape} (expected H x W or H x W x C)", path)
    _check_array_header(path, img.shape, img.dtype, "the file")
    return img


def read_json(path: str | Path, what: str = "file") -> object:
    """Parse a JSON file; unreadable or malformed files raise :class:`InputError` naming the
    file and, for syntax errors, the line and column.

    Refused before parsing: anything but a readable regular file, files over
    :data:`MAX_JSON_BYTES`; while parsing: nesting deeper than Python's recursion limit, a key
    given twice in one object, a whole number of more than 300 digits. UTF-8 (with or without a
    byte-order mark), UTF-16 and UTF-32 are read.
    """
    import json

    path = check_input_file(path, what)
    size = path.stat().st_size
    if size > MAX_JSON_BYTES:
        raise InputError(f"{_human(size)}, too large for a plantreg JSON file (limit {_human(MAX_JSON_BYTES)})", path)
    try:
        # bytes: json detects UTF-8 (with or without the byte-order mark Windows editors write),
        # UTF-16 and UTF-32 as RFC 8259 allows; a key given twice is refused (readers disagree on
        # which one counts: Python's json keeps the last, others the first)
        return json.loads(path.read_bytes(), object_pairs_hook=_no_duplicate_keys, parse_int=_bounded_int)
    except _DuplicateKey as e:
        raise InputError(f"key {e.args[0]!r} appears twice in one JSON object; JSON readers disagree on which "
                         "one counts: keep one", path) from None
    except _HugeNumber as e:
        raise InputError(f"holds a whole number of {e.args[0]} digits, beyond any value plantreg reads (and beyond "
                         "a float: 1e308)", path) from None
    except json.JSONDecodeError as e:
        raise InputError(f"not valid JSON (line {e.lineno}, column {e.colno}: {e.msg})", path) from None
    except RecursionError:
        raise InputError("JSON nested too deeply (a corrupt or hostile file?)", path) from None
    except UnicodeDecodeError as e:
        raise InputError(f"cannot read: not UTF-8 text ({e.reason} at byte {e.start})", path) from None
    except OSError as e:
        raise InputError(f"cannot read ({e.strerror or e})", path) from None


class _DuplicateKey(ValueError):
    pass


class _HugeNumber(ValueError):
    pass


def _bounded_int(text: str) -> int:
    """A JSON integer; one of more than 300 digits is refused (it cannot become a float, which
    every numeric check does, and Python refuses to parse more than 4300 digits at all)."""
    digits = len(text.lstrip("-"))
    if digits > 300:
        raise _HugeNumber(digits)
    return int(text)


def _no_duplicate_keys(pairs: list[tuple[str, object]]) -> dict:
    d = dict(pairs)
    if len(d) != len(pairs):
        seen: set[str] = set()
        raise _DuplicateKey(next(k for k, _ in pairs if k in seen or seen.add(k)))
    return d


def read_json_object(path: str | Path, what: str = "file") -> dict:
    """:func:`read_json` for files whose top level must be a JSON object."""
    d = read_json(path, what)
    if not isinstance(d, dict):
        raise InputError(f"the top level must be a JSON object {{...}}, got {_json_type(d)}", path)
    return d


def _json_type(v: object) -> str:
    return {dict: "an object", list: "a list", str: "a string", bool: "true/false", type(None): "null",
            int: "a number", float: "a number"}.get(type(v), type(v).__name__)


# ---------------------------------------------------------------------- atomic writing
def _umask() -> int:
    """The process umask, read without changing it (os.umask would race with other threads)."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("Umask:"):
                return int(line.split()[1], 8)
    except (OSError, ValueError):
        pass
    return 0o022


def _publish(tmp: Path, is_dir: bool = False) -> None:
    """Give a temp file/folder the permissions of an ordinary new one before it is moved into
    place (mkstemp/mkdtemp make 0600/0700, which would hide results on shared disks)."""
    os.chmod(tmp, (0o777 if is_dir else 0o666) & ~_umask())


def _renamed(e: OSError, tmp: Path, final: Path) -> OSError:
    """``e`` with the temporary name in its file name replaced by the user's path: the user never
    asked for ``.out.XXXX.part`` and must be told which of *their* files could not be written
    (also when the error had no file name, as a full disk during ``write()``)."""
    name = str(e.filename) if e.filename is not None else ""
    t = str(tmp)
    if name == t or name.startswith(t + os.sep):
        name = str(final) + name[len(t):]
    elif not name:
        name = str(final)
    else:
        return e
    new = OSError(e.errno, e.strerror or str(e), name)
    return new


@contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; on success move it into place, on error remove it.

    The temporary name is hidden and ends with the real suffix (``.name.XXXX.part.png``), so
    writers that choose the format by suffix (``cv2.imwrite``, ``tifffile``, ``np.save``) work
    and nothing half-written ever carries the final name. OS errors (disk full, permission) name
    ``path``, never the temporary name.
    """
    path = check_destination(path)
    tmp: Path | None = None
    try:
        with signals.deferred():  # a temporary is never created without its name being known here
            tmp = temp_beside(path)
        yield tmp
        _publish(tmp)
        os.replace(tmp, path)
    except BaseException as e:
        if tmp is not None:
            tmp.unlink(missing_ok=True)
        if isinstance(e, OSError):
            raise _renamed(e, tmp or path, path) from None
        raise


def has_write_bits(folder: str | Path) -> bool:
    """Whether ``folder`` has any write bit set (False when it cannot be examined). A folder the
    user made read-only is left untouched also by root."""
    try:
        return bool(Path(folder).stat().st_mode & 0o222)
    except OSError:
        return False


def atomic_write_text(path: str | Path, text: str) -> None:
    """Write ``text`` as UTF-8, atomically. A file name that is not UTF-8 (Python holds its bytes
    as surrogates, ``re\\udcffc``) is written back as its own bytes, so the text names the file
    that exists (``batch.csv``'s recording column)."""
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8", errors="surrogateescape")


def write_png(path: str | Path, img: np.ndarray) -> None:
    """Write a uint8/uint16 image (H, W) or RGB (H, W, 3) atomically."""
    img = np.asarray(img)
    if img.ndim == 3 and img.shape[2] == 3:
        img = cv2.cvtColor(img, cv2.COLOR_RGB2BGR)
    ok, buf = cv2.imencode(".png", img)
    if not ok:
        raise OSError(errno.EINVAL, "PNG encoder failed", str(path))
    with atomic_path(path) as tmp:
        tmp.write_bytes(buf.tobytes())  # written by Python: a full disk is an OSError naming the file


def write_tiff(path: str | Path, img: np.ndarray) -> None:
    """Write (H, W) or (H, W, C) as one TIFF page atomically, dtype kept.

    Band-last arrays are written with contiguous samples (tifffile would otherwise make a 3-D
    grey array into H pages of W x C), so GDAL, QGIS and ImageJ see H x W with C bands.
    uint8 (H, W, 3) is written as RGB.
    """
    import tifffile

    a = np.ascontiguousarray(img)
    kw: dict = {"photometric": "minisblack"}
    if a.ndim == 3:
        kw["planarconfig"] = "contig"
        if a.shape[2] == 3 and a.dtype == np.uint8:
            kw["photometric"] = "rgb"
    with atomic_path(path) as tmp:
        tifffile.imwrite(tmp, a, **kw)


def _nonempty_dir(p: Path) -> bool:
    try:
        with os.scandir(p) as it:
            return any(True for _ in it)
    except OSError:
        return False


@contextmanager
def atomic_output_dir(out: str | Path, overwrite: bool = False) -> Iterator[Path]:
    """Build an output folder under a temporary name and move it into place at the end.

    If ``out`` exists and is not empty it is an error unless ``overwrite`` (then the old folder
    is replaced only after the new one is complete, and put back if the new one cannot be moved
    in). A failed, cancelled or terminated run leaves nothing at ``out`` that looks complete and
    no temporary folder beside it; OS errors name paths under ``out``, never the temporary name.
    ``--overwrite`` onto a symbolic link replaces the link with a folder; its target is untouched.
    """
    out = check_destination(out, folder=True)
    if out.is_dir() and any(out.iterdir()) and not overwrite:
        raise InputError("output folder exists and is not empty (choose another, or allow overwriting)", out)
    tmp: Path | None = None
    old: Path | None = None
    try:
        with signals.deferred():
            tmp = temp_beside(out, folder=True)
        yield tmp
        _publish(tmp, is_dir=True)
        with signals.deferred():
            if not overwrite and _nonempty_dir(out):
                # made by someone else while this run worked (checked empty at the start): not ours to remove
                raise InputError("output folder was created and filled by someone else while plantreg worked; "
                                 "it is left as it is and nothing was written (choose another, or allow "
                                 "overwriting)", out)
            if os.path.lexists(out):
                old = temp_beside(out, folder=True, suffix=".old")
                os.replace(out, old / "x")
            try:
                os.replace(tmp, out)
            except BaseException:
                if old is not None and os.path.lexists(old / "x") and not os.path.lexists(out):
                    os.replace(old / "x", out)  # put the previous result back
                raise
            tmp = None
            if old is not None:
                shutil.rmtree(old, ignore_errors=True)
                old = None
    except BaseException as e:
        if tmp is not None:
            shutil.rmtree(tmp, ignore_errors=True)
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)
        if isinstance(e, OSError):
            raise _renamed(e, tmp or out, out) from None
        raise


@contextmanager
def atomic_files(paths: list[str | Path], remove: list[str | Path] = ()) -> Iterator[dict[Path, Path]]:
    """Write several files as one transaction: yields {final path: temporary path beside it}.

    The caller writes every temporary file; when the block ends without error all of them are
    moved into place together (signals held meanwhile), and the existing files in ``remove``
    (stale members of a previous set) disappear with them. Existing files are moved aside first
    and restored if any move fails, so the previous set survives any failure and the new set is
    never half there. On error every temporary file is removed. OS errors name the final paths.
    """
    finals = [Path(p) for p in paths]
    stale = [Path(p) for p in remove if os.path.lexists(p) and Path(p) not in finals]
    if len({p.absolute() for p in finals}) != len(finals):
        raise InputError("two outputs of this command would be the same file: "
                         + ", ".join(sorted({str(p) for p in finals if finals.count(p) > 1})))
    tmps: dict[Path, Path] = {}
    moved: list[tuple[Path, Path]] = []  # (final, backup)
    placed: list[Path] = []
    current: Path | None = None
    try:
        for p in finals:
            current = p
            check_destination(p)
            with signals.deferred():
                tmps[p] = temp_beside(p)
        current = None
        yield dict(tmps)
        with signals.deferred():
            try:
                for p in finals + stale:
                    current = p
                    if os.path.lexists(p):
                        b = temp_beside(p, suffix=".old")
                        os.replace(p, b)
                        moved.append((p, b))
                for p in finals:
                    current = p
                    _publish(tmps[p])
                    os.replace(tmps[p], p)
                    placed.append(p)
                current = None
            except BaseException:
                for p in placed:
                    Path(p).unlink(missing_ok=True)
                for p, b in moved:
                    os.replace(b, p)
                moved = []
                raise
            for _p, b in moved:
                b.unlink(missing_ok=True)
    except BaseException as e:
        for t in tmps.values():
            t.unlink(missing_ok=True)
        if isinstance(e, OSError):
            for p, t in tmps.items():
                if e.filename is not None and str(e.filename) == str(t):
                    raise _renamed(e, t, p) from None
            if e.filename is None:
                raise _renamed(e, current or finals[0], current or finals[0]) from None
        raise


# ---------------------------------------------------------------------- compressed, tiled TIFF
#: Lossless codecs of :func:`write_tiff_tiled` (name -> TIFF compression, TIFF predictor).
#: ``deflate-fp`` (default): compression 8 (Adobe deflate, level 1) with the floating-point
#: predictor (3) -- read by tifffile (with imagecodecs), GDAL, libtiff and Bio-Formats (Fiji);
#: ``deflate``: the same without predictor (~15 % larger, same time; also read by readers
#: without predictor support); ``zstd``: compression 50000, ~3x faster to encode than deflate,
#: ~as large as plain deflate, read by GDAL >= 2.3, libtiff >= 4.0.10 and tifffile (with
#: imagecodecs), *not* by ImageJ/Fiji. Measured in ``benchmarks/bench_outputs.py``.
TIFF_CODECS = {"deflate-fp": (8, 3), "deflate": (8, 1), "zstd": (50000, 1)}
TIFF_CODEC_DEFAULT = "deflate-fp"


def tiff_tile_edge(channels: int, itemsize: int = 4, target_bytes: int = 1 << 18) -> int:
    """Square tile edge (multiple of 16, 16..512) giving tiles of about ``target_bytes``."""
    edge = int(np.sqrt(target_bytes / max(1, channels * itemsize))) // 16 * 16
    return int(min(512, max(16, edge)))


def _tile_encoder(codec: str, samples_axis: bool):
    """bytes of one tile (th, tw[, C]) array in TIFF codec ``codec`` (see :data:`TIFF_CODECS`)."""
    try:
        import imagecodecs
    except ImportError:  # plain zlib: slower, same files
        imagecodecs = None
    if codec not in TIFF_CODECS:
        raise ValueError(f"unknown TIFF codec {codec!r}; choose from {', '.join(TIFF_CODECS)}")
    if codec != "deflate" and imagecodecs is None:
        raise InputError(f"TIFF codec {codec} needs the imagecodecs package (pip install imagecodecs)")
    axis = -2 if samples_axis else -1  # the row axis of a tile, as tifffile and libtiff predict along it
    if codec == "zstd":
        return lambda t: imagecodecs.zstd_encode(t, level=1)
    if imagecodecs is not None and imagecodecs.DEFLATE.available:  # libdeflate: ~2.5x zlib's speed
        deflate = lambda b: imagecodecs.deflate_encode(b, level=1)  # noqa: E731
    else:
        import zlib

        deflate = lambda b: zlib.compress(np.ascontiguousarray(b).tobytes(), 1)  # noqa: E731
    if codec == "deflate-fp":
        return lambda t: deflate(imagecodecs.floatpred_encode(np.ascontiguousarray(t), axis=axis))
    return deflate


def write_tiff_tiled(path: str | Path, shape: tuple[int, ...], dtype, tile_of, *,
                     codec: str = TIFF_CODEC_DEFAULT, fill: float = np.nan, workers: int | None = None) -> None:
    """Write an (H, W) or (H, W, C) image as one tiled, losslessly compressed TIFF page, atomically.

    ``tile_of(r0, r1, c0, c1)`` returns the image's block rows r0..r1-1, columns c0..c1-1
    ((r1-r0, c1-c0[, C]) of ``dtype``), or None when the block holds only ``fill`` -- such tiles
    are encoded once and repeated, so a mostly empty image costs little time, and the image
    never needs to exist in memory as a whole. Samples are contiguous (GDAL: INTERLEAVE=PIXEL),
    square tiles of ~256 KB. ``codec``: see :data:`TIFF_CODECS`. Tiles are encoded in
    ``workers`` threads (the codecs release the GIL; default: the cores, at most 4).
    """
    import os
    from collections import deque
    from concurrent.futures import ThreadPoolExecutor

    import tifffile

    dtype = np.dtype(dtype)
    H, W = int(shape[0]), int(shape[1])
    C = int(np.prod(shape[2:])) if len(shape) > 2 else 1
    edge = tiff_tile_edge(C, dtype.itemsize)
    tshape = (edge, edge, C) if len(shape) > 2 else (edge, edge)
    if codec == "deflate-fp" and dtype.kind != "f":
        codec = "deflate"  # the floating-point predictor is for floats only
    encode_tile = _tile_encoder(codec, len(shape) > 2)
    empty = encode_tile(np.full(tshape, fill, dtype=dtype))
    blocks = [(r, c) for r in range(0, H, edge) for c in range(0, W, edge)]

    def encode(rc: tuple[int, int]) -> bytes:
        r0, c0 = rc
        r1, c1 = min(H, r0 + edge), min(W, c0 + edge)
        blk = tile_of(r0, r1, c0, c1)
        if blk is None:
            return empty
        blk = np.asarray(blk, dtype=dtype).reshape((r1 - r0, c1 - c0, *tshape[2:]))
        if blk.shape != tshape:  # edge tiles are padded to full size
            full = np.full(tshape, fill, dtype=dtype)
            full[: r1 - r0, : c1 - c0] = blk
            blk = full
        return encode_tile(np.ascontiguousarray(blk))

    n_workers = workers if workers is not None else min(4, os.cpu_count() or 1)

    def encoded():
        if n_workers <= 1:
            yield from map(encode, blocks)
            return
        # a window of tasks of a few tiles each (~1 MB): the threads never wait for a batch to
        # drain, and a hand-off per tile (0.2 ms of work for a 16 x 16 x 204 tile) is not paid;
        # at most 2 x workers tasks are in flight (bounded memory)
        per = max(1, (1 << 20) // (int(np.prod(tshape)) * dtype.itemsize))
        groups = [blocks[a : a + per] for a in range(0, len(blocks), per)]
        with ThreadPoolExecutor(n_workers) as ex:
            pending: deque = deque()
            for g in groups:
                pending.append(ex.submit(lambda g=g: [encode(rc) for rc in g]))
                if len(pending) >= 2 * n_workers:
                    yield from pending.popleft().result()
            while pending:
                yield from pending.popleft().result()

    compression, predictor = TIFF_CODECS[codec]
    kw: dict = {"photometric": "minisblack"}
    if len(shape) > 2:
        kw["planarconfig"] = "contig"
    if predictor != 1:
        kw["predictor"] = predictor
    with atomic_path(path) as tmp:
        tifffile.imwrite(tmp, data=encoded(), shape=(H, W, C) if len(shape) > 2 else (H, W), dtype=dtype,
                         tile=(edge, edge), compression=compression, **kw)


def dense_tiles(a: np.ndarray, fill_is_nan: bool = True):
    """``tile_of`` for :func:`write_tiff_tiled` over an in-memory array (H, W[, C]): blocks that
    are entirely NaN are reported as empty (None)."""
    def tile_of(r0: int, r1: int, c0: int, c1: int):
        blk = a[r0:r1, c0:c1]
        if fill_is_nan and blk.dtype.kind == "f" and np.isnan(blk).all():
            return None
        return blk
    return tile_of
