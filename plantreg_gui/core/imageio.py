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

            img = tifffile.imread(path)
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


# ---------------------------------------------------------------------- atomic writing
def _tmp_beside(path: Path) -> Path:
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".part", dir=path.parent)
    os.close(fd)
    return Path(tmp)


@contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; on success move it into place, on error remove it.

    The temporary name keeps the real suffix last-but-one so writers that look at the suffix
    (``cv2.imwrite``, ``tifffile``) work: ``.name.png.XXXX.part`` -> pass ``tmp`` as is to
    writers that accept any name, or use :func:`atomic_path_suffixed`.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = _tmp_beside(path)
    try:
        yield tmp
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


@contextmanager
def atomic_path_suffixed(path: str | Path) -> Iterator[Path]:
    """Like :func:`atomic_path`, but the temporary file ends with the same suffix as ``path``."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp_s = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=f".part{path.suffix}", dir=path.parent)
    os.close(fd)
    tmp = Path(tmp_s)
    try:
        yield tmp
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


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
    """Write an array (H, W) or (H, W, C) as TIFF atomically, dtype kept."""
    import tifffile

    with atomic_path_suffixed(path) as tmp:
        tifffile.imwrite(tmp, np.asarray(img), photometric="minisblack" if np.asarray(img).ndim == 2 or np.asarray(img).shape[-1] != 3 else "rgb")


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
    old = None
    if out.exists():
        old = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".old", dir=out.parent))
        os.replace(out, old / "x")
    os.replace(tmp, out)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)
