"""Reading images of every modality, and writing files atomically.

Readers keep values as they are: float thermal stays float, 16-bit stays 16-bit, a 204-band
cube stays 204 bands. Arrays are (H, W) or (H, W, C), band-last. Colour images read with
OpenCV are returned as RGB (not OpenCV's BGR).
"""

from __future__ import annotations

import os
import shutil
import tempfile
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

import cv2
import numpy as np

from .errors import InputError

IMAGE_SUFFIXES = (".npy", ".png", ".jpg", ".jpeg", ".tif", ".tiff", ".hdr")


def read_image(path: str | Path) -> np.ndarray:
    """Read ``.npy``, ``.png``, ``.jpg``, ``.tif``/``.tiff`` or an ENVI ``.hdr`` cube.

    Returns (H, W) or (H, W, C) in the file's dtype. Raises :class:`InputError` naming the
    file when it is missing, unreadable or not an image.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError("file not found", path)
    suffix = path.suffix.lower()
    try:
        if suffix == ".npy":
            img = np.load(path, allow_pickle=False)
        elif suffix in (".png", ".jpg", ".jpeg"):
            img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
            if img is None:
                raise InputError("not a readable image", path)
            if img.ndim == 3 and img.shape[2] == 3:
                img = cv2.cvtColor(img, cv2.COLOR_BGR2RGB)
            elif img.ndim == 3 and img.shape[2] == 4:
                img = cv2.cvtColor(img, cv2.COLOR_BGRA2RGBA)
        elif suffix in (".tif", ".tiff"):
            import tifffile

            with tifffile.TiffFile(path) as tf:
                series = tf.series[0]
                img = series.asarray()
                axes = series.axes
            if img.ndim == 3 and axes.endswith("SYX"):
                # planar-separate multi-band TIFF (GDAL's INTERLEAVE=BAND): tifffile gives bands
                # first; plantreg's arrays are band-last
                img = np.moveaxis(img, 0, -1)
        elif suffix == ".hdr":
            import spectral.io.envi as envi

            img = np.asarray(envi.open(str(path)).load())
        else:
            raise InputError(
                f"unsupported image type '{suffix}' (plantreg reads {', '.join(IMAGE_SUFFIXES)})", path
            )
    except InputError:
        raise
    except Exception as e:  # the libraries raise many kinds; the user needs the file and the reason
        raise InputError(f"cannot read image ({type(e).__name__}: {e})", path) from None
    img = np.asarray(img)
    if img.ndim == 3 and img.shape[2] == 1:
        img = img[:, :, 0]
    if img.ndim not in (2, 3) or img.size == 0:
        raise InputError(f"not an image: array of shape {img.shape} (expected H x W or H x W x C)", path)
    return img


def read_json(path: str | Path) -> object:
    """Parse a JSON file; unreadable or malformed files raise :class:`InputError` naming the
    file and, for syntax errors, the line and column."""
    import json

    path = Path(path)
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as e:
        raise InputError(f"not valid JSON (line {e.lineno}, column {e.colno}: {e.msg})", path) from None
    except (OSError, UnicodeDecodeError) as e:
        raise InputError(f"cannot read ({e})", path) from None


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


@contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; on success move it into place, on error remove it.

    The temporary name is hidden and ends with the real suffix (``.name.XXXX.part.png``), so
    writers that choose the format by suffix (``cv2.imwrite``, ``tifffile``, ``np.save``) work
    and nothing half-written ever carries the final name.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp_s = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=f".part{path.suffix}", dir=path.parent)
    os.close(fd)
    tmp = Path(tmp_s)
    try:
        yield tmp
        _publish(tmp)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


#: The same as :func:`atomic_path` (kept for callers that want to say the suffix matters).
atomic_path_suffixed = atomic_path


def atomic_write_text(path: str | Path, text: str) -> None:
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")


def write_png(path: str | Path, img: np.ndarray) -> None:
    """Write a uint8/uint16 image (H, W) or RGB (H, W, 3) atomically."""
    img = np.asarray(img)
    if img.ndim == 3 and img.shape[2] == 3:
        img = cv2.cvtColor(img, cv2.COLOR_RGB2BGR)
    with atomic_path_suffixed(path) as tmp:
        if not cv2.imwrite(str(tmp), img):
            raise OSError(f"{path}: PNG encoder failed")


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
    with atomic_path_suffixed(path) as tmp:
        tifffile.imwrite(tmp, a, **kw)


@contextmanager
def atomic_output_dir(out: str | Path, overwrite: bool = False) -> Iterator[Path]:
    """Build an output folder under a temporary name and move it into place at the end.

    If ``out`` exists and is not empty it is an error unless ``overwrite`` (then the old folder
    is replaced only after the new one is complete). A failed or cancelled run leaves nothing
    at ``out`` that looks complete.
    """
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise InputError("output path exists and is not a folder", out)
    if out.is_dir() and any(out.iterdir()) and not overwrite:
        raise InputError("output folder exists and is not empty (choose another, or allow overwriting)", out)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".part", dir=out.parent))
    try:
        yield tmp
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    _publish(tmp, is_dir=True)
    old = None
    if out.exists():
        old = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".old", dir=out.parent))
        os.replace(out, old / "x")
    os.replace(tmp, out)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)


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
        with ThreadPoolExecutor(n_workers) as ex:
            for a in range(0, len(blocks), 4 * n_workers):  # bounded number of tiles in flight
                yield from ex.map(encode, blocks[a : a + 4 * n_workers])

    compression, predictor = TIFF_CODECS[codec]
    kw: dict = {"photometric": "minisblack"}
    if len(shape) > 2:
        kw["planarconfig"] = "contig"
    if predictor != 1:
        kw["predictor"] = predictor
    with atomic_path_suffixed(path) as tmp:
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
