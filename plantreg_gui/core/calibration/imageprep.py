"""Images of any kind -> the 8-bit grey image a board detector works on, at a working scale.

Colour -> luma, multi-band cubes -> band mean, pseudo-colour (palette) thermal images -> palette
index (:func:`to_scalar`); 16-bit and float (thermal) -> percentiles 0.5 / 99.5 stretched to
0..255 (:func:`to_gray`); background removal with local contrast normalisation for lamp-heated
boards (:func:`flatten`); the working scale (:func:`work_scale`: large images downscaled, tiny
ones upscaled) and the mapping of corners back to image pixels.
"""

from __future__ import annotations

import cv2
import numpy as np

#: Thermal palettes recognised in pseudo-colour images: name -> control points (position 0..1,
#: R, G, B); the rest come from OpenCV's colour maps. "iron" is FLIR's ironbow (black, blue,
#: magenta, orange, yellow, white), the default of most thermal cameras.
_PALETTE_POINTS = {
    "iron": [(0.0, 0, 0, 10), (0.10, 5, 0, 70), (0.14, 10, 0, 105), (0.20, 50, 0, 140), (0.28, 100, 0, 152),
             (0.36, 150, 0, 156), (0.42, 190, 8, 140), (0.48, 212, 38, 100), (0.54, 222, 58, 55),
             (0.60, 232, 80, 15), (0.66, 242, 110, 2), (0.72, 247, 145, 0), (0.80, 251, 185, 0),
             (0.86, 252, 215, 20), (0.92, 252, 238, 110), (1.0, 255, 252, 235)],
}
_CV_PALETTES = ("jet", "rainbow", "inferno", "magma", "plasma", "turbo", "hot", "viridis", "hsv")
#: a 3-channel image is read as a palette image when the median distance of its colours to the
#: palette's curve is below this (RGB units of 0..255); JPEG and resampling blur colours a little
PALETTE_TOL = 14.0
#: ... and its colours are not close to grey (median channel spread above this)
GREY_SPREAD = 12.0
#: ... and an unknown palette (colours along one line) only when they are this saturated; a
#: photograph's colours are less so and it is read by its luma
PALETTE_SPREAD = 40.0
#: colours sampled for the quick "on no palette" test before the full one
PRECHECK_SAMPLES = 400
#: :func:`flatten` stretches local contrast up to this many times the image's median local
#: contrast (the board's checker stands out, the background's noise does not)
FLAT_NOISE_FLOOR = 3.0


def _palettes() -> dict[str, np.ndarray]:
    """name -> (256, 3) float32 RGB of every known thermal palette (built once)."""
    if _PALETTE_CACHE:
        return _PALETTE_CACHE
    x = np.linspace(0.0, 1.0, 256)
    for name, pts in _PALETTE_POINTS.items():
        a = np.asarray(pts, float)
        _PALETTE_CACHE[name] = np.stack([np.interp(x, a[:, 0], a[:, k]) for k in (1, 2, 3)], 1).astype(np.float32)
    ramp = np.arange(256, dtype=np.uint8).reshape(-1, 1)
    for name in _CV_PALETTES:
        bgr = cv2.applyColorMap(ramp, getattr(cv2, f"COLORMAP_{name.upper()}")).reshape(256, 3)
        _PALETTE_CACHE[name] = bgr[:, ::-1].astype(np.float32)
    return _PALETTE_CACHE


_PALETTE_CACHE: dict[str, np.ndarray] = {}


def _palette_index(colours: np.ndarray, lut: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Nearest palette entry of each colour (N, 3) -> (index (N,), distance (N,))."""
    from scipy.spatial import cKDTree

    d, i = cKDTree(lut).query(colours, k=1)
    return i, d


def to_scalar(image: np.ndarray) -> tuple[np.ndarray, str]:
    """Any image -> float32 (H, W) scalar field and how it was made.

    (H, W) of any dtype: as it is ("grey" for 8-bit, "16-bit", "float"). Multi-band cubes: band
    mean. Colour (H, W, 3|4): decided from the data -- colours near grey: luma ("grey");
    colours on a known thermal palette's curve (median distance below :data:`PALETTE_TOL`): each
    pixel's palette index ("palette iron"), i.e. the temperature order, not the luma of a rainbow
    (which folds: yellow and blue of a jet palette have similar luma); other strongly coloured
    images whose colours lie along one line: their first principal component oriented with
    luma ("colour PC1", only for saturated colours: a photograph is read by its luma); anything else: luma ("luma").
    """
    img = np.asarray(image)
    if img.ndim == 2:
        kind = "grey" if img.dtype == np.uint8 else "16-bit" if img.dtype.kind in "ui" else "float"
        return img.astype(np.float32), kind
    if img.shape[2] not in (3, 4):  # hyperspectral: the band mean has the best SNR for a grey board
        return np.nanmean(img.astype(np.float32), axis=2), "band mean"
    h, w = img.shape[:2]
    if img.dtype == np.uint8:  # the common case: decide on a sample before converting everything
        small = np.ascontiguousarray(img[:: max(1, h // 64), :: max(1, w // 64), :3])
        spread = small.max(2).astype(np.int16) - small.min(2)
        if np.median(spread) < GREY_SPREAD:
            return _luma8(img), "grey"
        top = 255.0
    else:
        top = 65535.0 if img.dtype == np.uint16 else max(float(np.nanmax(img[:, :, :3])), 1e-12)
    i = np.random.default_rng(0).integers(0, h * w, min(h * w, 4000))
    sample = img[i // w, i % w, :3].astype(np.float32) * np.float32(255.0 / top)
    sample = sample[np.all(np.isfinite(sample), axis=1)]

    def rgb() -> np.ndarray:
        a = img[:, :, :3].astype(np.float32)
        return a if top == 255.0 else a * np.float32(255.0 / top)

    def luma() -> np.ndarray:
        return _luma8(img) if img.dtype == np.uint8 else rgb() @ np.array([0.299, 0.587, 0.114], np.float32)

    if len(sample) == 0 or np.median(sample.max(1) - sample.min(1)) < GREY_SPREAD:
        return luma(), "grey"
    if _far_from_palettes(sample[:: max(1, len(sample) // PRECHECK_SAMPLES)]):
        return _luma_or_pc1(rgb, luma, sample)
    best, best_d = None, np.inf
    for name, lut in _palettes().items():
        d = float(np.median(_palette_index(sample, lut)[1]))
        if d < best_d:
            best, best_d = name, d
    if best_d < PALETTE_TOL:
        # map the image's distinct colours (a palette image has few) instead of every pixel
        flat = rgb().reshape(-1, 3)
        packed = np.round(np.clip(flat, 0, 255)).astype(np.int32) @ np.array([65536, 256, 1], np.int32)
        uniq, inv = np.unique(packed, return_inverse=True)
        cols = np.stack([uniq >> 16, (uniq >> 8) & 255, uniq & 255], 1).astype(np.float32)
        idx = _palette_index(cols, _palettes()[best])[0].astype(np.float32)
        return idx[inv.ravel()].reshape(img.shape[:2]), f"palette {best}"
    return _luma_or_pc1(rgb, luma, sample)


def _luma8(img: np.ndarray) -> np.ndarray:
    """8-bit RGB(A) (H, W, 3|4) -> its luma, float32 (H, W)."""
    return cv2.cvtColor(np.ascontiguousarray(img[:, :, :3]), cv2.COLOR_RGB2GRAY).astype(np.float32)


def _far_from_palettes(sample: np.ndarray) -> bool:
    """Whether colours (N, 3) are clearly on no known palette: the median distance to every
    palette above twice :data:`PALETTE_TOL` on a small sample (a photograph; spares the full test,
    which builds a search tree per palette)."""
    s2 = np.sum(sample.astype(np.float64) ** 2, axis=1)[:, None]
    for lut in _palettes().values():
        lut = lut.astype(np.float64)
        d2 = np.min(s2 - 2.0 * sample @ lut.T + np.sum(lut**2, axis=1)[None, :], axis=1)
        if float(np.median(d2)) < (2.0 * PALETTE_TOL) ** 2:
            return False
    return True


def _luma_or_pc1(rgb, luma, sample: np.ndarray) -> tuple[np.ndarray, str]:
    """A colour image on no known palette: the first principal component of strongly coloured
    images whose colours lie along one line ("colour PC1"), else the luma. ``rgb``, ``luma``:
    functions making the image's float RGB (H, W, 3) and luma (H, W)."""
    centred = sample - sample.mean(0)
    _, sv, vt = np.linalg.svd(centred, full_matrices=False)
    saturated = np.median(sample.max(1) - sample.min(1)) > PALETTE_SPREAD
    if saturated and sv[0] ** 2 > 0.9 * float(np.sum(sv**2)):  # colours along one line: its coordinate
        axis = vt[0] if vt[0] @ np.array([0.299, 0.587, 0.114]) >= 0 else -vt[0]
        return (rgb() @ axis.astype(np.float32)).astype(np.float32), "colour PC1"
    return luma(), "luma"


def _stretch(f: np.ndarray, lo_pct: float = 0.5, hi_pct: float = 99.5) -> np.ndarray:
    """float (H, W) -> uint8, percentiles ``lo_pct``/``hi_pct`` to 0/255 (non-finite -> low end)."""
    finite = np.isfinite(f)
    if not finite.any():
        return np.zeros(f.shape, np.uint8)
    if f.dtype == np.uint8 and finite.all():
        return np.ascontiguousarray(f)
    sub = f[finite] if f.size <= 1 << 20 else f[finite][:: max(1, f.size >> 20)]
    lo, hi = np.percentile(sub, [lo_pct, hi_pct])
    g = np.where(finite, f, lo).astype(np.float32)
    return np.clip((g - lo) * (255.0 / max(float(hi - lo), 1e-12)), 0, 255).astype(np.uint8)


def flatten(f: np.ndarray, sigma: float) -> np.ndarray:
    """Remove the low-frequency background of a scalar image (a lamp's hot spot, vignetting) and
    normalise local contrast: ``h = f - G(f)``, ``z = h / sqrt(G(h^2))`` with ``G`` a Gaussian of
    ``sigma`` px (about half a board square: the checker survives, the background does not; the
    contrast becomes the same over the whole board however faint the checker is; the floor
    :data:`FLAT_NOISE_FLOOR` keeps flat background noise down). Noise is smoothed first (a
    Gaussian of up to 1 px). (H, W) float -> uint8 (H, W), z = +-2 -> 0..255."""
    g = np.asarray(f, np.float32)
    finite = np.isfinite(g)
    if not finite.all():
        g = np.where(finite, g, np.median(g[finite]) if finite.any() else 0.0).astype(np.float32)
    pre = min(1.0, sigma / 4.0)
    if pre >= 0.5:
        g = cv2.GaussianBlur(g, (0, 0), pre)
    hp = g - cv2.GaussianBlur(g, (0, 0), sigma)
    sd = np.sqrt(cv2.GaussianBlur(hp * hp, (0, 0), sigma))
    # flat regions (a wall, the sky) are not stretched to full contrast: their noise would hide
    # the board; the floor is a multiple of the typical local contrast (mostly background)
    floor = FLAT_NOISE_FLOOR * float(np.median(sd)) + 1e-6 * (float(np.abs(hp).max()) + 1e-12)
    z = hp / np.maximum(sd, floor)
    return np.clip((z + 2.0) * (255.0 / 4.0), 0, 255).astype(np.uint8)


def to_gray(image: np.ndarray, enhance: bool = False) -> np.ndarray:
    """Any image (H, W), (H, W, 3|4) or a cube (H, W, B), of any dtype -> uint8 grey (H, W):
    :func:`to_scalar` stretched between its 0.5 and 99.5 percentiles; CLAHE with ``enhance``."""
    img = np.asarray(image)
    if img.ndim == 3 and img.shape[2] in (3, 4) and img.dtype == np.uint8:
        f, kind = to_scalar(img)
        g = (np.clip(np.round(f), 0, 255).astype(np.uint8) if kind in ("grey", "luma") else _stretch(f))
    else:
        g = _stretch(to_scalar(img)[0])
    if enhance:
        g = cv2.createCLAHE(clipLimit=3.0, tileGridSize=(8, 8)).apply(g)
    return np.ascontiguousarray(g)


#: Detection runs on an image whose longer side is at most this (corners are then refined at
#: full resolution) and at least :data:`MIN_SIDE` (tiny thermal images are upscaled first). The
#: SB detector's time grows with the image's area, but at 640 px the corners refined at full size
#: on a hand-held foil board (ZED 2i) landed up to 16 px from those found at full size.
WORK_SIDE = 1280
MIN_SIDE = 480

def work_scale(size: tuple[int, int]) -> float:
    """Scale (work px per image px) of the image detection runs on, for an image (w, h)."""
    side = max(size)
    if side > WORK_SIDE:
        return WORK_SIDE / side
    if side < MIN_SIDE:
        return float(int(np.ceil(MIN_SIDE / side)))
    return 1.0


def _resize(a: np.ndarray, s: float) -> np.ndarray:
    if s == 1.0:
        return a
    h, w = a.shape[:2]
    size = (max(1, round(w * s)), max(1, round(h * s)))
    return cv2.resize(a, size, interpolation=cv2.INTER_AREA if s < 1 else cv2.INTER_CUBIC)


def _to_image_px(c: np.ndarray, s: float) -> np.ndarray:
    """Corners (N, 2) in an image resized by ``s`` -> in the original image (pixel centres)."""
    return ((c + 0.5) / s - 0.5).astype(np.float32)

