"""Board corner detection with a unique corner order across cameras.

Images of any modality are first turned into 8-bit grey (:func:`to_gray`): colour -> luma,
multi-band cubes -> band mean, 16-bit and float (thermal) -> percentiles 0.5 / 99.5 stretched to
0..255; optional CLAHE for low-contrast images.

Chessboards: ``cv2.findChessboardCornersSB`` (robust to low contrast, finds positive and negative
boards alike), the classic ``findChessboardCorners`` as a fallback; then ``cornerSubPix`` with a
window sized to the local square size (:func:`refine_corners`: halves the error on rendered boards).
ChArUco: ``cv2.aruco.CharucoDetector``; corners keep their board ids.

**Corner order rule** (chessboards). A detector may return the grid starting at any of its four
corners. :func:`canonical_order` fixes it in two steps:

1. *Handedness*: the printed side faces the camera, so the board's x axis (corner 0 -> 1) and y
   axis (corner 0 -> ``columns``) must turn clockwise in the image (``cross > 0`` in pixel
   coordinates, v down). If not, the rows are reversed (a mirrored order).
2. *Colour*: the first interior square (between corners 0, 1, ``columns``, ``columns+1``) is
   black on the printed board (see :mod:`.board`). We compare the mean grey of all interior squares
   that must be black with those that must be white; with the board's *polarity* (``inverted``:
   a heated board in a thermal camera glows where the print is black) the expected relation is
   known, and if it does not hold the order is rotated by 180 degrees (reversed).

Step 2 needs an asymmetric board (``columns + rows`` odd; e.g. 15 x 8): a symmetric one looks the
same rotated, so its order falls back to "first corner nearest the image's top-left" and cameras
may disagree -- :class:`~.board.Board` reports ``is_symmetric`` so the UI can warn. The polarity
cannot be read from a single image (a negative board rotated by 180 degrees looks exactly like
the positive one), so it comes from :class:`DetectOptions` ``invert`` or, when that is None,
from the camera's modality (thermal = inverted).

Length: everything that turns an image into ordered board corners -- the scalar conversion
(palettes), the automatic variants, the ordering rule, the worker pool and the detections cache,
whose key is this module's :data:`DETECT_VERSION` and its options.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator

import hashlib
import json
import stat

import cv2
import numpy as np

from ..camera import modality as _modality
from ..errors import InputError, PlantregError
from ..io.imageio import atomic_write_text, has_write_bits, read_image
from ..progress import Reporter, ensure_reporter
from .board import Board

FOUND, FAILED, MISSING = "found", "failed", "missing"
#: Changes whenever detection can give other results for the same image and options: cached
#: detections (``detections.json``, :class:`DetectionCache`) of another version are detected again.
DETECT_VERSION = 4
DETECTORS = ("auto", "classic")


@dataclass
class DetectOptions:
    """Per-image detection options.

    ``invert``: board polarity. True = the board appears as a negative (heated board in a thermal
    camera), False = normal print, None = decided by the camera's modality (thermal -> True).
    Detection itself always tries the image and its negative; ``invert`` decides the corner order.
    ``enhance``: apply CLAHE (local contrast) before detection, for faint thermal boards.
    ``detector`` (chessboards): ``"auto"`` = ``findChessboardCornersSB`` with the classic detector
    as a fallback; ``"classic"`` = OpenCV's classic pipeline only (``findChessboardCorners`` +
    ``cornerSubPix`` with an 11 x 11 half-window, as OpenCV's ``stereo_calib`` sample does) --
    kept for comparison with published figures; its large window is biased where foreshortened
    squares are smaller than ~24 px.
    """

    invert: bool | None = None
    enhance: bool = False
    detector: str = "auto"

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {"invert": self.invert, "enhance": bool(self.enhance)}
        if self.detector != "auto":
            d["detector"] = self.detector
        return d

    @classmethod
    def from_dict(cls, d: Any) -> "DetectOptions":
        if not isinstance(d, dict):
            raise ValueError("detection options must be an object")
        inv = d.get("invert")
        det = str(d.get("detector", "auto"))
        if det not in DETECTORS:
            raise ValueError(f"detector must be one of {', '.join(DETECTORS)}")
        return cls(None if inv is None else bool(inv), bool(d.get("enhance", False)), det)


@dataclass
class Detection:
    """Result of one image. ``corners`` (N, 2) float32 in board order (chessboard: all
    ``columns * rows`` corners; ChArUco: the corners found, ids in ``ids`` (N,) int32), None unless
    ``status == "found"``. ``image_size`` (w, h). ``inverted`` = the polarity used for ordering.
    ``path`` the image file (None for in-memory images).

    How the board was found (see :data:`VARIANTS`): ``variant`` the preparation that found it
    ("plain", "flat", ...; "" when nothing was tried), ``conversion`` how the image became a
    scalar ("grey", "16-bit", "float", "palette iron", "colour PC1", "luma", "band mean"),
    ``scale`` the working scale (2 = upscaled twice, 0.46 = downscaled; corners are always in
    image pixels)."""

    pose: str
    camera: str
    status: str
    reason: str
    corners: np.ndarray | None
    ids: np.ndarray | None
    image_size: tuple[int, int]
    inverted: bool
    path: Path | None = None
    options: DetectOptions = field(default_factory=DetectOptions)
    variant: str = ""
    conversion: str = ""
    scale: float = 1.0

    @property
    def variant_text(self) -> str:
        """How the board was found, for people: "background removed, palette iron, upscaled 4x"."""
        parts = [VARIANT_TEXT.get(self.variant, self.variant)] if self.variant else []
        if self.conversion and self.conversion not in ("grey", "luma"):
            parts.append(self.conversion)
        if self.scale > 1:
            parts.append(f"upscaled {self.scale:g}x")
        elif self.scale < 1:
            parts.append(f"detected at {self.scale:.2g}x, refined at full size")
        return ", ".join(parts)

    @property
    def found(self) -> bool:
        return self.status == FOUND

    @property
    def key(self) -> tuple[str, str]:
        return (self.pose, self.camera)

    def object_points(self, board: Board) -> np.ndarray:
        """Board-frame points (N, 3) matching ``corners``."""
        obj = board.object_points()
        return obj if self.ids is None else obj[self.ids]


# ---------------------------------------------------------------------- image preparation
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
    if img.dtype == np.uint8:  # the common case: decide on a sample before converting everything
        small = np.ascontiguousarray(img[:: max(1, img.shape[0] // 64), :: max(1, img.shape[1] // 64), :3])
        spread = small.max(2).astype(np.int16) - small.min(2)
        if np.median(spread) < GREY_SPREAD:
            return cv2.cvtColor(np.ascontiguousarray(img[:, :, :3]), cv2.COLOR_RGB2GRAY).astype(np.float32), "grey"
    rgb = img[:, :, :3].astype(np.float32)
    if img.dtype != np.uint8:
        top = 65535.0 if img.dtype == np.uint16 else max(float(np.nanmax(rgb)), 1e-12)
        rgb = rgb * (255.0 / top)
    luma = rgb @ np.array([0.299, 0.587, 0.114], np.float32)
    flat = rgb.reshape(-1, 3)
    rng = np.random.default_rng(0)
    sample = flat[rng.integers(0, len(flat), min(len(flat), 4000))]
    sample = sample[np.all(np.isfinite(sample), axis=1)]
    if len(sample) == 0 or np.median(sample.max(1) - sample.min(1)) < GREY_SPREAD:
        return luma, "grey"
    best, best_d = None, np.inf
    for name, lut in _palettes().items():
        d = float(np.median(_palette_index(sample, lut)[1]))
        if d < best_d:
            best, best_d = name, d
    if best_d < PALETTE_TOL:
        # map the image's distinct colours (a palette image has few) instead of every pixel
        packed = np.round(np.clip(flat, 0, 255)).astype(np.int32) @ np.array([65536, 256, 1], np.int32)
        uniq, inv = np.unique(packed, return_inverse=True)
        cols = np.stack([uniq >> 16, (uniq >> 8) & 255, uniq & 255], 1).astype(np.float32)
        idx = _palette_index(cols, _palettes()[best])[0].astype(np.float32)
        return idx[inv.ravel()].reshape(img.shape[:2]), f"palette {best}"
    centred = sample - sample.mean(0)
    _, sv, vt = np.linalg.svd(centred, full_matrices=False)
    saturated = np.median(sample.max(1) - sample.min(1)) > PALETTE_SPREAD
    if saturated and sv[0] ** 2 > 0.9 * float(np.sum(sv**2)):  # colours along one line: its coordinate
        axis = vt[0] if vt[0] @ np.array([0.299, 0.587, 0.114]) >= 0 else -vt[0]
        return (rgb @ axis.astype(np.float32)).astype(np.float32), "colour PC1"
    return luma, "luma"


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


# ---------------------------------------------------------------------- chessboard
def _square_means(gray: np.ndarray, corners: np.ndarray, board: Board) -> tuple[float, float]:
    """Mean grey of interior squares that must be black vs white (in the given order)."""
    g = corners.reshape(board.rows, board.columns, 2)
    centres = (g[:-1, :-1] + g[1:, :-1] + g[:-1, 1:] + g[1:, 1:]) / 4.0  # (rows-1, cols-1, 2)
    jj, ii = np.mgrid[0 : board.rows - 1, 0 : board.columns - 1]
    black = board.square_is_black(ii + 1, jj + 1)  # square between corners i..i+1 is a = i + 1
    h, w = gray.shape
    # sample a small cross around each centre (robust to blur and noise)
    d = 0.15 * (g[1:, 1:] - g[:-1, :-1])
    vals = []
    for f in (0.0, 1.0, -1.0):
        p = centres + f * d
        u = np.clip(np.round(p[..., 0]).astype(int), 0, w - 1)
        v = np.clip(np.round(p[..., 1]).astype(int), 0, h - 1)
        vals.append(gray[v, u].astype(np.float64))
    m = np.mean(vals, axis=0)
    return float(m[black].mean()), float(m[~black].mean())


def canonical_permutation(corners: np.ndarray, gray: np.ndarray, board: Board, inverted: bool) -> np.ndarray:
    """Indices (N,) that put chessboard corners (N, 2) in the board order (rule in the module
    docstring): ``corners[perm]`` is ordered."""
    idx = np.arange(board.rows * board.columns).reshape(board.rows, board.columns)
    g = np.asarray(corners, np.float32).reshape(board.rows, board.columns, 2)
    ex = g[0, -1] - g[0, 0]
    ey = g[-1, 0] - g[0, 0]
    if ex[0] * ey[1] - ex[1] * ey[0] < 0:  # mirrored: reverse the rows
        idx = idx[::-1]
    perm = idx.ravel()
    c = np.asarray(corners, np.float32).reshape(-1, 2)[perm]
    if board.is_symmetric:
        # no colour cue: first corner nearest the image's top-left
        if (c[-1, 0] + c[-1, 1]) < (c[0, 0] + c[0, 1]):
            perm = perm[::-1]
        return np.ascontiguousarray(perm)
    mb, mw = _square_means(gray, c, board)
    black_is_dark = mb < mw
    if black_is_dark == bool(inverted):  # the "black" squares have the wrong brightness
        perm = perm[::-1]
    return np.ascontiguousarray(perm)


def canonical_order(corners: np.ndarray, gray: np.ndarray, board: Board, inverted: bool) -> np.ndarray:
    """Reorder chessboard corners (N, 2) to the board order (rule in the module docstring)."""
    c = np.asarray(corners, np.float32).reshape(-1, 2)
    return np.ascontiguousarray(c[canonical_permutation(c, gray, board, inverted)])


_SB_ACC = cv2.CALIB_CB_ACCURACY


def _find_classic(gray: np.ndarray, pattern: tuple[int, int], win: int = 11) -> np.ndarray | None:
    for img in (gray, 255 - gray):
        ok, c = cv2.findChessboardCorners(img, pattern, flags=cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE)
        if ok:
            c = cv2.cornerSubPix(gray, c, (win, win), (-1, -1),
                                 (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 30, 0.01))
            return c.reshape(-1, 2)
    return None


def _find_chessboard(gray: np.ndarray, pattern: tuple[int, int], thorough: bool = True,
                     detector: str = "auto") -> np.ndarray | None:
    if detector == "classic":
        return _find_classic(gray, pattern)
    # CALIB_CB_NORMALIZE_IMAGE (histogram equalisation) hurts when a small board sits on a large
    # dark background (infrared), so plain first, normalised second, exhaustive last. The SB
    # detector finds positive and negative boards alike, so no inverted attempt is needed here.
    attempts = [(gray, _SB_ACC), (gray, _SB_ACC | cv2.CALIB_CB_NORMALIZE_IMAGE)]
    if thorough:
        attempts += [(gray, _SB_ACC | cv2.CALIB_CB_EXHAUSTIVE)]
    for img, flags in attempts:
        ok, c = cv2.findChessboardCornersSB(img, pattern, flags=flags)
        if ok:
            return c.reshape(-1, 2)
    if not thorough:
        return None
    # classic detector + sub-pixel refinement (handles some blurry images SB misses)
    return _find_classic(gray, pattern, win=5)


def refine_corners(gray: np.ndarray, corners: np.ndarray, board: Board, guard: bool = True) -> np.ndarray:
    """Polish chessboard corners (N, 2) with ``cv2.cornerSubPix``, its half-window 40 % of the
    smallest corner spacing in the image (so it never reaches a neighbouring corner). On rendered
    boards with known truth this halves the SB detector's error and removes its ~0.02 px bias.
    With ``guard``, a corner that would move by more than a third of the window keeps its
    position (without: the classic detector's rough corners, which must move)."""
    g = corners.reshape(board.rows, board.columns, 2)
    spacing = min(float(np.linalg.norm(np.diff(g, axis=0), axis=2).min()),
                  float(np.linalg.norm(np.diff(g, axis=1), axis=2).min()))
    w = int(np.clip(0.4 * spacing, 2, 15))
    c = cv2.cornerSubPix(gray.astype(np.float32), corners.reshape(-1, 1, 2).astype(np.float32).copy(), (w, w), (-1, -1),
                         (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 50, 1e-4)).reshape(-1, 2)
    if guard:
        moved = np.linalg.norm(c - corners, axis=1) > max(1.0, w / 3.0)
        c[moved] = corners[moved]
    return c


# ---------------------------------------------------------------------- automatic variants
#: Detection runs on an image whose longer side is at most this (corners are then refined at
#: full resolution) and at least :data:`MIN_SIDE` (tiny thermal images are upscaled first).
WORK_SIDE = 1280
MIN_SIDE = 480
#: What :func:`detect_image` tries, in this order, until the whole board is found: the scalar
#: image stretched ("plain"); with its background removed and its local contrast normalised at
#: two scales ("flat", "flat-fine"; :func:`flatten`); with CLAHE ("clahe"); flattened at twice the
#: size for small, far or steep boards ("fine-2x"); the exhaustive searches ("thorough"); and,
#: for downscaled images, the full-resolution image ("full-res"). On each, the classic detector
#: (image and negative) then the SB detector (:func:`_find_any`).
VARIANTS = ("plain", "flat", "flat-fine", "clahe", "fine-2x", "thorough", "full-res")
VARIANT_TEXT = {"plain": "plain", "flat": "background removed", "flat-fine": "background removed (fine)",
                "clahe": "CLAHE", "fine-2x": "background removed (fine)", "thorough": "exhaustive search", "full-res": "full resolution",
                "classic": "OpenCV classic"}


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


def _square_px(size: tuple[int, int], board: Board) -> float:
    """A board square's size in px when the board fills about half the image's shorter side."""
    return 0.5 * min(size) / (max(board.columns, board.rows) + 1)


def _variant_images(f: np.ndarray, board: Board, enhance: bool):
    """Yield (variant, uint8 image, thorough, zoom) in the order tried; ``f`` the working-scale
    scalar, ``zoom`` the image's size relative to ``f`` (2: "fine-2x", small squares doubled)."""
    plain = _stretch(f)
    sq = _square_px((f.shape[1], f.shape[0]), board)
    order = ["clahe", "plain", "flat", "flat-fine"] if enhance else ["plain", "flat", "flat-fine", "clahe"]
    made: dict[str, np.ndarray] = {}
    for v in order:
        if v == "plain":
            made[v] = plain
        elif v == "flat":
            made[v] = flatten(f, max(2.0, sq / 2.0))
        elif v == "flat-fine":
            made[v] = flatten(f, max(1.5, sq / 4.0))
        else:
            made[v] = cv2.createCLAHE(clipLimit=3.0, tileGridSize=(8, 8)).apply(plain)
        yield v, made[v], False, 1.0
    if max(f.shape) <= WORK_SIDE:  # a small, far or steep board: its squares doubled
        yield "fine-2x", flatten(_resize(f, 2.0), max(1.5, sq / 3.0)), False, 2.0
    yield "thorough", made["plain"], True, 1.0
    yield "thorough", made["flat"], True, 1.0


def _flat_like(f: np.ndarray, variant: str, board: Board) -> np.ndarray:
    """The full-resolution image of a flattened ``variant`` (its sigma in full-size pixels)."""
    sq = _square_px((f.shape[1], f.shape[0]), board)
    return flatten(f, max(2.0, sq / 2.0) if variant != "flat-fine" else max(1.5, sq / 4.0))


def _saddles_ok(img: np.ndarray, corners: np.ndarray, board: Board, min_share: float = 0.9) -> bool:
    """Whether the grid's corners are checker saddle points: around each, the diagonal quadrants
    alike and the other two of the other colour, for at least ``min_share`` of the corners. A grid
    one square too large (a 10 x 7 "found" on a 9 x 6 board, its outer corners on the board's
    edge, where a square meets the margin) fails this."""
    g = np.asarray(corners, np.float64).reshape(board.rows, board.columns, 2)
    ex = np.gradient(g, axis=1)  # along a row, one corner spacing
    ey = np.gradient(g, axis=0)
    sm = cv2.GaussianBlur(img.astype(np.float32), (0, 0), 1.0)
    h, w = sm.shape

    def at(p):
        u = np.clip(np.round(p[..., 0]).astype(int), 0, w - 1)
        v = np.clip(np.round(p[..., 1]).astype(int), 0, h - 1)
        return sm[v, u]
    a, b = at(g + 0.3 * (ex + ey)), at(g - 0.3 * (ex + ey))
    c, d = at(g + 0.3 * (ex - ey)), at(g - 0.3 * (ex - ey))
    dc = (c + d - a - b) / 2.0
    sep = np.where(dc > 0, np.minimum(c, d) - np.maximum(a, b), np.minimum(a, b) - np.maximum(c, d))
    saddle = sep > 0.3 * np.abs(dc)  # both diagonal pairs clearly apart (a margin is neither)
    return float(saddle.mean()) >= min_share


#: a grid whose corner leaves the line of its neighbours by more than this share of their spacing
#: may have a corner that is not where the detector put it (a glinting foil square pulled SB's
#: corner onto the board's edge, 60 px away: 0.45-0.95 on the ZED 2i views); correct grids on the
#: real sets reach 0.37 (a steep hand-held view; the Lepton's k1 = -0.4: 0.30). Only a choice
#: between two detectors' grids, never a refusal.
MAX_IRREGULARITY = 0.4


def grid_irregularity(corners: np.ndarray, board: Board) -> float:
    """The largest second difference of the chessboard grid ``corners`` (N, 2) along its rows and
    columns, relative to the local corner spacing: ~0.1-0.3 for a real lens, ~1 for a corner
    that sits a square away from its place."""
    g = np.asarray(corners, np.float64).reshape(board.rows, board.columns, 2)
    worst = 0.0
    for a in (0, 1):
        if g.shape[a] < 3:
            continue
        gg = np.moveaxis(g, a, 0)
        d2 = np.linalg.norm(gg[:-2] - 2 * gg[1:-1] + gg[2:], axis=-1)
        span = np.linalg.norm(gg[2:] - gg[:-2], axis=-1) / 2.0
        worst = max(worst, float(np.max(d2 / np.maximum(span, 1e-9))))
    return worst


def _settle_classic(img: np.ndarray, corners: np.ndarray, board: Board) -> np.ndarray | None:
    """The classic detector's corners (the quads' corners, ~1 px off) moved onto the saddle
    points; None when one would move further than a fifth of the corner spacing (at least 2 px):
    then it did not sit on a corner it could find."""
    c = refine_corners(img, corners, board, guard=False)
    g = corners.reshape(board.rows, board.columns, 2)
    spacing = min(float(np.linalg.norm(np.diff(g, axis=0), axis=2).min()),
                  float(np.linalg.norm(np.diff(g, axis=1), axis=2).min()))
    if float(np.linalg.norm(c - corners, axis=1).max()) > max(2.0, 0.2 * spacing):
        return None
    return c


def _find_any(img: np.ndarray, pattern: tuple[int, int], thorough: bool,
              sb_first: bool = False) -> tuple[np.ndarray | None, str]:
    """Cheap first: the classic detector on the image and on its negative (it only finds dark
    squares on light; milliseconds on a clear board), then the SB detector (polarity-free,
    robust to blur and low contrast; its corners are refined later anyway), plain and normalised;
    when ``thorough``: the SB detector's exhaustive search. ``sb_first`` (upscaled tiny images,
    where SB is cheap and its start points refine better): SB before classic. Returns (corners
    (N, 2) or None, "classic" | "sb")."""
    def classic():
        for im in (img, 255 - img):
            ok, c = cv2.findChessboardCorners(im, pattern, flags=cv2.CALIB_CB_ADAPTIVE_THRESH
                                              | cv2.CALIB_CB_NORMALIZE_IMAGE)
            if ok:
                return c.reshape(-1, 2), "classic"
        return None, ""

    def sb():
        for fl in [0, cv2.CALIB_CB_NORMALIZE_IMAGE] if not thorough else [_SB_ACC | cv2.CALIB_CB_EXHAUSTIVE]:
            ok, c = cv2.findChessboardCornersSB(img, pattern, flags=fl)
            if ok:
                return c.reshape(-1, 2), "sb"
        return None, ""

    for step in ((sb,) if thorough else (sb, classic) if sb_first else (classic, sb)):
        c, how = step()
        if c is not None:
            return c, how
    return None, ""


def _detect_chessboard_auto(f: np.ndarray, board: Board, enhance: bool, inverted: bool):
    """The automatic variants on a scalar image ``f`` (H, W). Returns (corners (N, 2) in board
    order in image px, variant, scale) or (None, tried variants, scale)."""
    size = (f.shape[1], f.shape[0])
    s = work_scale(size)
    fw = _resize(f, s)
    plain_w = _stretch(fw)
    # the saddle check runs on a linear image without the lamp's gradient (the flattened ones
    # make a board's dark surround look like squares)
    hp_w = fw - cv2.GaussianBlur(fw.astype(np.float32), (0, 0), max(2.0, _square_px((fw.shape[1], fw.shape[0]), board)))
    tried = []
    s0 = s
    for variant, img, thorough, zoom in _variant_images(fw, board, enhance):
        if variant not in tried:
            tried.append(variant)
        s = s0 * zoom
        # SB first everywhere: classic corners, even settled and refined, left the OpenCV stereo
        # sample's relative pose 0.17 deg from Bouguet's (SB's: 0.007 deg); on a faint flattened
        # board classic quads are several px off, beyond what cornerSubPix can pull back
        c, how = _find_any(img, board.pattern_size, thorough, sb_first=True)
        if c is None or not _saddles_ok(hp_w, c, board):
            continue
        if how == "sb" and grid_irregularity(c, board) > MAX_IRREGULARITY:
            # a corner off its grid line: the classic detector's grid when it is the regular one
            c2, how2 = _find_any(img, board.pattern_size, False)
            if how2 == "classic" and _saddles_ok(hp_w, c2, board) \
                    and grid_irregularity(c2, board) < grid_irregularity(c, board):
                # settled on the saddle points; on a glinting foil square a free refinement
                # wanders, then each corner moves only as far as the guard lets it
                c2s = _settle_classic(img, c2, board)
                c, how = (c2s if c2s is not None else refine_corners(img, c2, board)), "classic, regular grid"
        perm = canonical_permutation(c, img if variant != "clahe" else plain_w, board, inverted)
        # refined on the image that found them: on rendered lamp-heated boards with known truth the
        # flattened image gives smaller corner errors than the raw scalar (whose lamp gradient
        # biases cornerSubPix) or its linear high-pass
        if how == "classic":  # its corners are the quads' corners: bring them onto the saddle points first
            c = _settle_classic(img, c, board)
            if c is None:  # a corner ran off (faint, or beside a hot edge): the SB detector decides
                c, how = _find_any(img, board.pattern_size, False, sb_first=True)
                if how != "sb" or not _saddles_ok(img, c, board):
                    continue
                perm = canonical_permutation(c, img if variant != "clahe" else plain_w, board, inverted)
        if s > 1.0:  # upscaled: refine on the upscaled variant image, then back to image px
            c = _to_image_px(refine_corners(img, c, board), s)
        elif s < 1.0:  # downscaled: refine on the full-resolution image (cornerSubPix needs no stretch)
            c = refine_corners(f if variant in ("plain", "clahe") else _flat_like(f, variant, board), _to_image_px(c, s),
                               board)
        else:
            c = refine_corners(img, c, board)
        return c[perm], variant, s
    s = s0
    if s < 1.0:  # a board too small for the downscaled image
        tried.append("full-res")
        img = _stretch(f)
        c, how = _find_any(img, board.pattern_size, False)
        if c is None:
            img = flatten(f, max(2.0, _square_px(size, board) / 2.0))
            c, how = _find_any(img, board.pattern_size, False)
        if c is not None and _saddles_ok(img, c, board):
            perm = canonical_permutation(c, img, board, inverted)
            if how == "classic":
                c2 = _settle_classic(img, c, board)
                c = c if c2 is None else c2
            return refine_corners(img, c, board)[perm], "full-res", 1.0
    return None, tried, s


def _detect_charuco(gray: np.ndarray, board: Board):
    det = cv2.aruco.CharucoDetector(board.charuco())
    best = (None, None)
    for img in (gray, 255 - gray):
        ch_corners, ch_ids, _, _ = det.detectBoard(img)
        if ch_ids is not None and len(ch_ids) >= 4 and (best[1] is None or len(ch_ids) > len(best[1])):
            best = (ch_corners.reshape(-1, 2).astype(np.float32), ch_ids.ravel().astype(np.int32))
    return best


def _detect_charuco_auto(f: np.ndarray, board: Board, enhance: bool):
    """ChArUco on the plain, background-removed and CLAHE images; the one with most corners
    (stops when all are found). Returns (corners, ids, variant)."""
    plain = _stretch(f)
    n_all = (board.columns) * (board.rows)
    best = (None, None, "")
    sq = _square_px((f.shape[1], f.shape[0]), board)
    makers = [("plain", lambda: plain), ("flat", lambda: flatten(f, max(2.0, sq / 2.0))),
              ("clahe", lambda: cv2.createCLAHE(clipLimit=3.0, tileGridSize=(8, 8)).apply(plain))]
    if enhance:
        makers = makers[2:] + makers[:2]
    for variant, make in makers:
        c, ids = _detect_charuco(make(), board)
        if c is not None and (best[1] is None or len(ids) > len(best[1])):
            best = (c, ids, variant)
        if best[1] is not None and len(best[1]) >= n_all:
            break
    return best


def detect_image(image: np.ndarray, board: Board, options: DetectOptions | None = None,
                 modality: str | None = None) -> Detection:
    """Detect the board in one image. Returns a :class:`Detection` with empty ``pose``/``camera``
    (status ``found`` or ``failed`` with a reason). ``modality`` only matters when
    ``options.invert`` is None (thermal -> inverted polarity).

    The image becomes a scalar (:func:`to_scalar`: palette images by palette index), then the
    variants of :data:`VARIANTS` are tried in order until the whole board is found; which one
    found it is recorded in ``variant``/``conversion``/``scale``."""
    options = options or DetectOptions()
    inverted = options.invert if options.invert is not None else _modality.inverted_board(modality)
    img = np.asarray(image)
    size = (int(img.shape[1]), int(img.shape[0]))
    f, conversion = to_scalar(img)

    def fail(reason: str, variant: str = "") -> Detection:
        return Detection("", "", FAILED, reason, None, None, size, inverted, None, options, variant, conversion)

    finite = np.isfinite(f)
    if not finite.any() or float(np.nanmax(f)) == float(np.nanmin(f)):
        return fail("the image is blank (one value everywhere)")
    if board.type == "charuco":
        corners, ids, variant = _detect_charuco_auto(f, board, options.enhance)
        if corners is None:
            return fail("no ChArUco corners found (check dictionary and marker size, or the image is too dark/blurred)")
        if len(ids) < 6:
            return fail(f"only {len(ids)} ChArUco corners found (need 6)")
        if cv2.aruco.CharucoBoard.checkCharucoCornersCollinear(board.charuco(), ids.reshape(-1, 1)):
            return fail("the ChArUco corners found are collinear (too little of the board is visible)")
        order = np.argsort(ids)
        return Detection("", "", FOUND, "", corners[order], ids[order], size, inverted, None, options,
                         variant, conversion)
    if options.detector == "classic":
        gray = to_gray(img, options.enhance)
        corners = _find_classic(gray, board.pattern_size)
        if corners is None:
            return fail(f"no {board.columns}x{board.rows} inner-corner chessboard found by the classic detector",
                        "classic")
        corners = canonical_order(corners, gray, board, inverted)
        return Detection("", "", FOUND, "", corners.astype(np.float32), None, size, inverted, None, options,
                         "classic", conversion)
    corners, variant, scale = _detect_chessboard_auto(f, board, options.enhance, inverted)
    if corners is None:
        return fail(f"no {board.columns}x{board.rows} inner-corner chessboard found (tried: {', '.join(variant)}"
                    f"{'' if scale == 1 else f'; detected at {scale:g}x'}); check the board size and that "
                    "the whole board is in the image")
    return Detection("", "", FOUND, "", corners.astype(np.float32), None, size, inverted, None, options,
                     variant, conversion, scale)


def suggest_board_size(images: list[np.ndarray], board: Board) -> tuple[int, int] | None:
    """When nothing is found: try nearby inner-corner counts (the usual mistake is counting
    squares, i.e. one too many each way) on a few images; return the first (columns, rows) that
    is found, or None."""
    c, r = board.columns, board.rows
    candidates = [(c - 1, r - 1), (r, c), (c - 1, r), (c, r - 1), (c + 1, r + 1), (r - 1, c - 1),
                  (c + 1, r), (c, r + 1), (c - 2, r - 2)]
    seen = set()
    for cand in candidates:
        if cand in seen or min(cand) < 2 or cand == (c, r):
            continue
        seen.add(cand)
        for img in images[:3]:
            if _find_chessboard(to_gray(img), cand, thorough=False) is not None:
                return cand
    return None


# ---------------------------------------------------------------------- sessions
def detect_view(session, pose, camera: str, options: DetectOptions | None = None,
                image: np.ndarray | None = None) -> Detection:
    """Detect one (pose, camera) of a session (a missing image gives status ``missing``).
    ``image``: the view's image if already read. Unreadable files raise :class:`InputError`."""
    path = pose.images.get(camera)
    if path is None:
        return Detection(pose.name, camera, MISSING, f"no image of camera '{camera}' in this pose",
                         None, None, (0, 0), False, None, options or DetectOptions())
    opts = options or DetectOptions()
    if opts.invert is None:
        opts = DetectOptions(session.default_inverted(camera), opts.enhance, opts.detector)
    img = read_image(path) if image is None else image
    det = detect_image(img, session.board, opts, session.cameras.get(camera))
    det.pose, det.camera, det.path = pose.name, camera, Path(path)
    det.options = options or DetectOptions()
    return det


def detect_session(session, options: dict[tuple[str, str], DetectOptions] | None = None,
                   progress: Reporter | None = None,
                   views: list[tuple[str, str]] | None = None) -> Iterator[Detection]:
    """Detect every (pose, camera) of the session (:func:`detect_views`: cached, or in worker
    processes); a generator yielding each :class:`Detection` in session order (poses in order,
    cameras in session order) as soon as it and those before it are done. ``options`` per image
    override the session's stored review options. ``views`` restricts the work to some (pose,
    camera) pairs. Each step is a cancellation point (``progress`` raises :class:`Cancelled`);
    stopping the iteration also stops the work. Unreadable images raise :class:`InputError`
    naming the file.
    """
    wanted = None if views is None else set(views)
    order = [(p.name, c) for p in session.poses for c in session.cameras if wanted is None or (p.name, c) in wanted]
    ready: dict[tuple[str, str], Detection] = {}
    i = 0
    for det, _ in detect_views(session, order, options, progress):
        ready[det.key] = det
        while i < len(order) and order[i] in ready:
            yield ready.pop(order[i])
            i += 1


def worker_count(n_jobs: int) -> int:
    """Processes for ``n_jobs`` images: the cores this process may use (``PLANTREG_WORKERS``
    overrides), at most one per image."""
    import os

    try:
        n = int(os.environ.get("PLANTREG_WORKERS", "0"))
    except ValueError:
        n = 0
    if n <= 0:
        try:
            n = len(os.sched_getaffinity(0))
        except (AttributeError, OSError):
            n = os.cpu_count() or 1
    return max(1, min(n, n_jobs))


def _pool_init() -> None:
    """In each detection process: the CLI's signal handling (core/jobs/signals.py: a signal to the
    process group ends a worker quietly; the parent decides what the run does). One OpenCV
    thread each: the processes already use every core."""
    from .. import signals

    signals.child_init()
    cv2.setNumThreads(1)


def _detect_one(session, pose: str, camera: str, options: DetectOptions | None, thumb: int,
                cached: Detection | None, unreadable: str = "raise") -> tuple[Detection, np.ndarray | None]:
    """One image in a worker: its detection (or ``cached``) and a ``thumb``-pixel thumbnail.
    ``unreadable="fail"``: an unreadable image gives a failed detection saying why."""
    p = session.pose(pose)
    path = p.images.get(camera)
    try:
        img = read_image(path) if path is not None and (cached is None or thumb) else None
    except InputError as e:
        if unreadable == "raise":
            raise
        return Detection(pose, camera, FAILED, f"unreadable image: {e}", None, None, (0, 0), False, path,
                         options or DetectOptions()), None
    det = cached if cached is not None else detect_view(session, p, camera, options, image=img)
    if not thumb or img is None:
        return det, None
    from .preview import thumbnail

    return det, thumbnail(img, thumb)


def detect_views(session, views: list[tuple[str, str]] | set | None = None,
                 options: dict[tuple[str, str], DetectOptions] | None = None,
                 progress: Reporter | None = None, thumbnails: int = 0, processes: bool | None = None,
                 use_cache: bool = True, unreadable: str = "raise") -> Iterator[tuple[Detection, np.ndarray | None]]:
    """Detect ``views`` (all (pose, camera) pairs if None) and yield ``(Detection, thumbnail)``
    as each is done (thumbnail None unless ``thumbnails`` > 0 px).

    Detections cached in the session's ``detections.json`` (:class:`DetectionCache`) whose image, board and
    options are unchanged are yielded first without detecting; the rest run in a pool of
    ``spawn`` worker processes (:func:`worker_count`; ``processes`` True always uses one, e.g. for
    a GUI whose thread must keep the GIL, False never, None when more than one image and core).
    Progress counts images; cancelling ``progress`` (or closing the generator) terminates the
    workers at once. New results are added to the cache as they arrive and it is saved at the
    end, also after a cancel or an error. Unreadable images raise :class:`InputError`, or with
    ``unreadable="fail"`` become failed detections saying why (the wizard goes on with the others)."""
    import concurrent.futures as cf

    progress = ensure_reporter(progress)
    opts = session.detect_options()
    opts.update(options or {})
    wanted = None if views is None else set(views)
    todo = [(p.name, c) for p in session.poses for c in session.cameras if wanted is None or (p.name, c) in wanted]
    n = max(1, len(todo))
    cache = DetectionCache(session) if use_cache else None
    done, ok = 0, False
    work: list[tuple[tuple[str, str], Detection | None, dict | None]] = []
    progress(0.0, f"checking {len(todo)} images")
    for key in todo:
        progress.check()
        o = opts.get(key) or DetectOptions()
        k = image_key(session, key[0], key[1], o) if cache is not None else None
        hit = cache.get(key[0], key[1], k, opts.get(key) or DetectOptions()) if cache is not None else None
        if hit is not None and not thumbnails:
            done += 1
            progress(done / n, f"{key[0]}/{key[1]}: cached")
            yield hit, None
        else:
            work.append((key, hit, k))
    try:
        n_proc = worker_count(len(work))
        use_pool = processes if processes is not None else (len(work) > 1 and n_proc > 1)
        if not work:
            ok = True
            return
        if not use_pool:
            for key, hit, k in work:
                progress.check()
                det, thumb = _detect_one(session, key[0], key[1], opts.get(key), thumbnails, hit, unreadable)
                if hit is None and cache is not None:
                    cache.put(det, k)
                done += 1
                progress(done / n, f"{key[0]}/{key[1]}: {det.status}")
                yield det, thumb
            ok = True
            return
        from .. import signals

        pool = cf.ProcessPoolExecutor(max_workers=n_proc, mp_context=signals.spawn_context(), initializer=_pool_init)
        clean = False
        try:
            futs = {pool.submit(_detect_one, session, key[0], key[1], opts.get(key), thumbnails, hit, unreadable):
                    (key, k, hit)
                    for key, hit, k in work}
            pending = set(futs)
            while pending:
                progress.check()
                finished, pending = cf.wait(pending, timeout=0.1, return_when=cf.FIRST_COMPLETED)
                for fut in finished:
                    key, k, hit = futs[fut]
                    try:
                        det, thumb = fut.result()
                    except cf.process.BrokenProcessPool:
                        from ..errors import PlantregError
                        from .. import signals

                        signals.check()  # the process group was signalled: say so, not "ended unexpectedly"
                        raise PlantregError("a corner detection process ended unexpectedly (out of memory?)") from None
                    if hit is None and cache is not None and not det.reason.startswith("unreadable image"):
                        cache.put(det, k)
                    done += 1
                    progress(done / n, f"{key[0]}/{key[1]}: {det.status}")
                    yield det, thumb
            clean = True
        finally:
            if clean:
                pool.shutdown(wait=True)
            else:  # cancelled, an error, a signal, or the consumer stopped: no worker may go on
                from .. import signals

                procs = signals.pool_processes(pool)
                pool.shutdown(wait=False, cancel_futures=True)
                # a worker may have been started while shutting down: take the list again
                procs += [p for p in signals.pool_processes(pool) if p not in procs]
                signals.stop_processes(procs, grace_s=2.0)
        ok = True
    finally:
        if cache is not None:
            cache.save()
    if ok:
        progress(1.0, "detection done")


def detection_summary(detections: dict[tuple[str, str], Detection]) -> dict[str, Any]:
    """The detection figures a report carries: per camera the images (not missing), boards found,
    the rate and how many were found by each variant; per image its status, variant, scalar
    conversion, working scale and the reason of a failure. JSON-ready."""
    cams: dict[str, dict[str, Any]] = {}
    views: dict[str, dict[str, Any]] = {}
    for (pose, cam), d in sorted(detections.items()):
        if d.status == MISSING:
            continue
        c = cams.setdefault(cam, {"images": 0, "found": 0, "rate": 0.0, "variants": {}})
        c["images"] += 1
        v: dict[str, Any] = {"status": d.status, "variant": d.variant, "conversion": d.conversion,
                             "scale": round(float(d.scale), 4)}
        if d.found:
            c["found"] += 1
            c["variants"][d.variant or "?"] = c["variants"].get(d.variant or "?", 0) + 1
        else:
            v["reason"] = d.reason
        views[f"{pose}:{cam}"] = v
    for c in cams.values():
        c["rate"] = c["found"] / c["images"] if c["images"] else 0.0
    return {"cameras": cams, "views": views}


# ---------------------------------------------------------------------- the detection cache
# Detections kept in the session folder (``detections.json``), so that a re-run, a
# recalibration after excluding views and the wizard's resume do not detect again.
#
# One entry per image, ``"POSE:CAMERA"`` -> ``{"key": ..., "detection": ...}``. The key holds
# everything the result depends on: the image file (path relative to the session, size,
# modification time in ns, BLAKE2b of its bytes), the board, the image's detection options, the
# polarity and modality used, and :data:`DETECT_VERSION`. Any change to one of them
# misses the cache and the image is detected again. The file is written atomically; a session
# folder that cannot be written (read-only media, permissions) simply has no cache, and a
# missing, corrupt or foreign ``detections.json`` is ignored (never an error: it is only a cache).
CACHE_FILE = "detections.json"
_FORMAT = "plantreg detections"


def image_key(session, pose: str, camera: str, options: DetectOptions) -> dict[str, Any] | None:
    """What a detection of (``pose``, ``camera``) depends on, or None when the image cannot be
    examined (missing, unreadable: detection reports that itself)."""
    path = session.pose(pose).images.get(camera)
    if path is None:
        return None
    try:
        st = Path(path).stat()
        if not stat.S_ISREG(st.st_mode):  # a FIFO would block the read: the reader names it
            return None
        h = hashlib.blake2b(digest_size=16)
        with open(path, "rb") as f:
            for block in iter(lambda: f.read(1 << 20), b""):
                h.update(block)
    except OSError:
        return None
    try:
        rel = str(Path(path).relative_to(session.folder))
    except ValueError:
        rel = str(path)
    inverted = options.invert if options.invert is not None else session.default_inverted(camera)
    return {"file": rel, "size": st.st_size, "mtime_ns": st.st_mtime_ns, "blake2b": h.hexdigest(),
            "board": session.board.to_dict(), "options": options.to_dict(), "inverted": bool(inverted),
            "modality": session.cameras.get(camera), "version": DETECT_VERSION}


def detection_to_dict(d: Detection) -> dict[str, Any]:
    return {"status": d.status, "reason": d.reason,
            "corners": None if d.corners is None else np.asarray(d.corners, float).round(4).tolist(),
            "ids": None if d.ids is None else np.asarray(d.ids).astype(int).tolist(),
            "image_size": list(d.image_size), "inverted": bool(d.inverted),
            "variant": d.variant, "conversion": d.conversion, "scale": float(d.scale)}


def detection_from_dict(d: dict[str, Any], pose: str, camera: str, path: Path | None,
                        options: DetectOptions) -> Detection:
    corners = None if d.get("corners") is None else np.asarray(d["corners"], np.float32).reshape(-1, 2)
    ids = None if d.get("ids") is None else np.asarray(d["ids"], np.int32)
    return Detection(pose, camera, str(d["status"]), str(d.get("reason", "")), corners, ids,
                     tuple(int(v) for v in d["image_size"]), bool(d["inverted"]), path, options,
                     str(d.get("variant", "")), str(d.get("conversion", "")), float(d.get("scale", 1.0)))


class DetectionCache:
    """The ``detections.json`` of one session (see the module docstring)."""

    def __init__(self, session) -> None:
        self.session = session
        self.path = Path(session.folder) / CACHE_FILE
        self.entries: dict[str, dict[str, Any]] = {}
        self.dirty = False
        try:
            d = json.loads(self.path.read_text(encoding="utf-8"))
            if isinstance(d, dict) and d.get("format") == _FORMAT and isinstance(d.get("images"), dict):
                self.entries = d["images"]
        except (OSError, ValueError, UnicodeDecodeError):
            pass

    def get(self, pose: str, camera: str, key: dict[str, Any] | None, options: DetectOptions) -> Detection | None:
        """The cached detection of the image if ``key`` matches, else None."""
        e = self.entries.get(f"{pose}:{camera}")
        if key is None or not isinstance(e, dict) or e.get("key") != key:
            return None
        try:
            return detection_from_dict(e["detection"], pose, camera, self.session.pose(pose).images.get(camera),
                                       options)
        except (KeyError, TypeError, ValueError):
            return None

    def put(self, det: Detection, key: dict[str, Any] | None) -> None:
        if key is None or det.status == "missing":
            return
        self.entries[f"{det.pose}:{det.camera}"] = {"key": key, "detection": detection_to_dict(det)}
        self.dirty = True

    def save(self) -> bool:
        """Write the file atomically if anything changed; False when the folder is not writable."""
        if not self.dirty:
            return True
        if not has_write_bits(self.path.parent):  # untouched, also for root (who may write anyway)
            return False
        known = {f"{p.name}:{c}" for p in self.session.poses for c in p.images}
        images = {k: v for k, v in sorted(self.entries.items()) if k in known}
        try:
            atomic_write_text(self.path, json.dumps({"format": _FORMAT, "version": DETECT_VERSION,
                                                     "images": images}) + "\n")
        except (OSError, PlantregError):  # a read-only session: no cache, no error
            return False
        self.dirty = False
        return True


def check_image_sizes(session, detections: dict[tuple[str, str], Detection]) -> dict[str, tuple[int, int]]:
    """The image size (w, h) of each camera; raises :class:`InputError` naming the first image
    whose size differs from the camera's other images."""
    sizes: dict[str, tuple[int, int, Path | None]] = {}
    for (pose, cam), d in sorted(detections.items()):
        if d.status == MISSING:
            continue
        if cam not in sizes:
            sizes[cam] = (*d.image_size, d.path)
        elif tuple(sizes[cam][:2]) != tuple(d.image_size):
            w, h, first = sizes[cam]
            raise InputError(
                f"image is {d.image_size[0]}x{d.image_size[1]} but the other images of camera '{cam}' "
                f"are {w}x{h} (e.g. {first}); one camera must always deliver the same size", d.path)
    return {k: (v[0], v[1]) for k, v in sizes.items()}
