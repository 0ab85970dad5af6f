"""Display rendering: any modality -> an (H, W, 3) uint8 RGB picture, plus case overlays and mosaics.

Pure numpy / OpenCV / matplotlib colormap tables (no Qt), so the GUI, the CLI previews and the
point-cloud colours all render the same way. Fast enough for interactive use on 4K images:
statistics (percentiles, PCA) are computed on a subsample of at most ~1e6 pixels, colour maps
are 256-entry lookup tables.

Single-band images go through a colour map (thermal: diverging blue-white-red as in the paper;
infrared grey; depth viridis), contrast stretched between two percentiles of the finite pixels.
NaN (not mapped) pixels are drawn in :data:`BACKGROUND_RGB`. Three-band images are RGB whatever
their modality (uint8 as they are, others stretched with one pair of limits for all channels so
hues are kept), see :func:`shows_as_rgb`. Cubes with other band counts are shown as PCA false
colour or as three chosen bands.

Length: one rendering path (limits, colour maps, PCA false colour, overlays, mosaics) that the
screen and the export share, so that an export looks exactly like the view; split, its parts
would only call each other.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import Mapping, Sequence

import cv2
import numpy as np

from ..registration import cases
from ..camera import modality as _modality
from ..registration.cases import AREA_NAMES, CASE_NAMES

#: Colour of pixels without a value (NaN): a neutral dark grey.
BACKGROUND_RGB: tuple[int, int, int] = (28, 28, 28)

#: Default colour map per canonical modality (matplotlib names), from :mod:`.modality`.
DEFAULT_CMAPS: dict[str, str] = {m.name: m.cmap for m in _modality.MODALITIES}

#: Case-map and area-map overlay colours (code -> RGB), from :mod:`.cases`; codes without an
#: overlay (P1, P6 background) are absent.
CASE_COLOURS: dict[int, tuple[int, int, int]] = dict(cases.CASE_COLOURS)
AREA_COLOURS: dict[int, tuple[int, int, int]] = dict(cases.AREA_COLOURS)

#: Legend labels per code (the same names as :mod:`.cases`).
CASE_LABELS: dict[int, str] = dict(CASE_NAMES)
AREA_LABELS: dict[int, str] = dict(AREA_NAMES)


def legend(kind: str = "cases", colours: Mapping[int, tuple[int, int, int]] | None = None
           ) -> list[tuple[int, str, tuple[int, int, int] | None]]:
    """Legend entries ``(code, label, rgb or None for 'no overlay')`` for ``kind`` 'cases' or 'areas'."""
    labels = CASE_LABELS if kind == "cases" else AREA_LABELS
    colours = (CASE_COLOURS if kind == "cases" else AREA_COLOURS) if colours is None else colours
    return [(c, labels[c], colours.get(c)) for c in sorted(labels)]


# ---------------------------------------------------------------------- statistics
_MAX_SAMPLES = 1_000_000
#: values per block of the per-pixel passes (float32: 1 MB, fits a core's cache)
_BLOCK_VALUES = 1 << 18


def _sample(values: np.ndarray, max_samples: int = _MAX_SAMPLES) -> np.ndarray:
    """A strided subsample of a 1-D array (deterministic, so displays do not flicker)."""
    step = max(1, int(np.ceil(values.shape[0] / max_samples)))
    return values[::step]


def _finite_values(img: np.ndarray, mask: np.ndarray | None) -> np.ndarray:
    """Finite values of ``img`` (H, W[, C]) under ``mask`` (H, W), flattened, subsampled. A
    :class:`~.hits.HitImage` without a mask is not expanded: its pixels without a hit are NaN
    and would be dropped anyway, so its ``values`` (M, C) are the pixels."""
    from ..registration.hits import HitImage

    if isinstance(img, HitImage) and mask is None:
        a = img.values
        a = _sample(a, max(1, _MAX_SAMPLES // a.shape[1])).ravel()
        return a[np.isfinite(a)]
    a = np.asarray(img)
    if mask is not None:
        a = a[np.asarray(mask, dtype=bool)]
    else:
        a = a.reshape(-1, *a.shape[2:]) if a.ndim > 2 else a.ravel()
    a = _sample(a, max(1, _MAX_SAMPLES // (a.shape[1] if a.ndim == 2 else 1)))
    a = a.ravel()
    if a.dtype.kind == "f":
        a = a[np.isfinite(a)]
    return a


def auto_limits(img: np.ndarray, percentiles: tuple[float, float] = (1, 99),
                mask: np.ndarray | None = None) -> tuple[float, float]:
    """Contrast limits ``(lo, hi)``: the given percentiles of the finite values of ``img``.

    ``img`` (H, W) or (H, W, C) (all channels pooled); ``mask`` (H, W) bool restricts the
    pixels. Returns ``(0, 1)`` when there is no finite value, and widens ``hi`` when all
    values are equal so that callers never divide by zero.
    """
    v = _finite_values(img, mask)
    if v.size == 0:
        return 0.0, 1.0
    lo, hi = np.percentile(v, [float(percentiles[0]), float(percentiles[1])])
    lo, hi = float(lo), float(hi)
    if not hi > lo:
        hi = lo + max(1.0, abs(lo) * 1e-6)
    return lo, hi


# ---------------------------------------------------------------------- colour maps
@lru_cache(maxsize=64)
def colormap_lut(name: str) -> np.ndarray:
    """(256, 3) uint8 lookup table of a matplotlib colour map."""
    from .cmap_tables import TABLES

    if name in TABLES:  # the common maps without importing matplotlib (start-up of a pipeline)
        return np.frombuffer(bytes.fromhex(TABLES[name]), dtype=np.uint8).reshape(256, 3).copy()
    import matplotlib

    cmap = matplotlib.colormaps[name]
    return np.ascontiguousarray((cmap(np.linspace(0.0, 1.0, 256))[:, :3] * 255.0 + 0.5).astype(np.uint8))


def any_channel(b: np.ndarray) -> np.ndarray:
    """``b.any(axis=-1)`` for (..., C) bool with few channels: an OR of the C planes, much faster
    than numpy's reduction along a short last axis; same values."""
    out = b[..., 0].copy()
    for c in range(1, b.shape[-1]):
        out |= b[..., c]
    return out


def _normalise_u8(img: np.ndarray, lo: float, hi: float) -> tuple[np.ndarray, np.ndarray | None]:
    """Scale (H, W[, C]) to 0..255 uint8 between ``lo`` and ``hi``; also returns the NaN mask (H, W)."""
    src = np.asarray(img)
    a = np.asarray(src, dtype=np.float32)
    is_float = src.dtype.kind == "f"
    scale = 255.0 / (hi - lo)
    s32, off32 = np.float32(scale), np.float32(lo * scale)
    out = np.empty(a.shape, np.uint8)
    nan = np.zeros(a.shape[:2], bool) if is_float else None
    # by blocks of rows that stay in the cache: the same float32 operations as on the whole image
    # (so the same bytes), faster on a 4K frame than whole-image passes through memory.
    # cv2.convertScaleAbs would fold negatives; do it in float, clip, cast (NaN pixels are painted later)
    rows = max(1, _BLOCK_VALUES // max(1, int(np.prod(a.shape[1:]))))
    u = np.empty((min(rows, a.shape[0]), *a.shape[1:]), np.float32)
    for r in range(0, a.shape[0], rows):
        blk = a[r : r + rows]
        ub = u[: len(blk)]
        np.multiply(blk, s32, out=ub)
        ub -= off32
        # clip to 0..255 with NaN -> 0 (fmax/fmin return the number where one operand is NaN)
        np.fmax(ub, np.float32(0.0), out=ub)
        np.fmin(ub, np.float32(255.0), out=ub)
        if is_float:
            bad = ~np.isfinite(blk)
            if bad.any():
                nan[r : r + rows] = bad if a.ndim == 2 else any_channel(bad)
        ub += np.float32(0.5)
        np.copyto(out[r : r + rows], ub, casting="unsafe")  # truncation, as astype(uint8)
    if nan is not None and not nan.any():
        nan = None
    return out, nan


def _paint_background(rgb: np.ndarray, mask: np.ndarray) -> None:
    """``rgb[mask] = BACKGROUND_RGB`` for (H, W, 3) uint8 ``rgb`` and (H, W) bool ``mask``, in place:
    OpenCV's masked copy, faster than numpy's ``copyto(where=)`` on a 4K view (mostly background)."""
    m = np.ascontiguousarray(mask, dtype=bool)
    if rgb.flags.c_contiguous and rgb.dtype == np.uint8 and rgb.ndim == 3 and rgb.shape[2] == 3:
        # by blocks of rows (each a contiguous slice, written in place): a background block of
        # the whole image would cost more to fill than the copy itself
        rows = max(1, _BLOCK_VALUES // max(1, rgb.shape[1] * 3))
        bg = np.empty((min(rows, rgb.shape[0]), *rgb.shape[1:]), np.uint8)
        bg[:] = BACKGROUND_RGB
        m8 = m.view(np.uint8)
        for r in range(0, rgb.shape[0], rows):
            dst = rgb[r : r + rows]
            cv2.copyTo(bg[: len(dst)], m8[r : r + rows], dst)
    else:
        np.copyto(rgb, np.asarray(BACKGROUND_RGB, dtype=rgb.dtype), where=m[..., None])


def _background(h: int, w: int) -> np.ndarray:
    """(h, w, 3) uint8 filled with :data:`BACKGROUND_RGB`, copied block by block (a broadcast
    assignment of the 3-value colour to a whole 4K image is ~10x slower)."""
    out = np.empty((h, w, 3), np.uint8)
    rows = max(1, _BLOCK_VALUES // max(1, w * 3))
    blk = np.empty((min(rows, h), w, 3), np.uint8)
    blk[:] = BACKGROUND_RGB
    for r in range(0, h, rows):
        dst = out[r : r + rows]
        dst[:] = blk[: len(dst)]
    return out


def _apply_lut(u8: np.ndarray, lut: np.ndarray) -> np.ndarray:
    """(H, W) uint8 indices -> (H, W, 3) uint8 through a (256, 3) table."""
    # cv2.LUT on a 3-channel copy is faster than numpy fancy indexing on 4K frames
    return cv2.LUT(cv2.merge([u8, u8, u8]), lut.reshape(256, 1, 3))


def colorize(img: np.ndarray, cmap: str = "gray", limits: tuple[float, float] | None = None,
             percentiles: tuple[float, float] = (1, 99), mask: np.ndarray | None = None) -> np.ndarray:
    """Single band (H, W) -> (H, W, 3) uint8 through colour map ``cmap``; NaN -> background."""
    lo, hi = limits if limits is not None else auto_limits(img, percentiles, mask)
    if not hi > lo:
        hi = lo + 1.0
    u8, nan = _normalise_u8(img, float(lo), float(hi))
    out = _apply_lut(u8, colormap_lut(cmap))
    if nan is not None:
        _paint_background(out, nan)
    return out


# ---------------------------------------------------------------------- multi-band
def _one_blas_thread():
    """A context in which BLAS/LAPACK run in one thread. Why: the PCA's products are small
    (a ~5000 x B covariance, a B x B eigen-decomposition); OpenBLAS's threads mostly spin
    waiting for each other there, several times the CPU of one thread on a busy machine."""
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # pragma: no cover - a dependency; without it, BLAS's own threads
        from contextlib import nullcontext

        return nullcontext()
    return threadpool_limits(1, user_api="blas")


def finite_rows(flat: np.ndarray) -> np.ndarray:
    """``np.isfinite(flat).all(axis=1)`` for (N, C) ``flat``, (N,) bool. A few channels (points,
    RGB) are checked plane by plane (see :func:`any_channel`: faster than the reduction along
    a short axis); many bands only in the rows whose first band is finite: a registered cube is NaN
    off the object (~85 % of its rows), and the full check of a 204-band cube is a pass over all
    its values."""
    if flat.dtype.kind != "f":
        return np.ones(len(flat), bool)
    ok = np.isfinite(flat[:, 0])
    if flat.shape[1] <= 4:
        for c in range(1, flat.shape[1]):
            ok &= np.isfinite(flat[:, c])
        return ok
    cand = np.flatnonzero(ok)
    step = max(1, (16 << 20) // (4 * flat.shape[1]))  # ~16 MB of values per chunk, never a copy of the cube
    if len(cand) > len(flat) // 2:  # mostly finite (e.g. hit values): plain row ranges
        for a in range(0, len(flat), step):
            ok[a : a + step] = np.isfinite(flat[a : a + step]).all(axis=1)
    else:
        for a in range(0, len(cand), step):
            c = cand[a : a + step]
            ok[c] = np.isfinite(flat[c, 1:]).all(axis=1)
    return ok


def pca_scores(cube: np.ndarray, mask: np.ndarray | None = None, n: int = 3) -> np.ndarray:
    """First ``n`` principal-component scores of a cube (H, W, B) -> (H, W, n) float32.

    Components are fitted on the pixels whose bands are all finite (and inside ``mask``); the
    sign of each component is fixed so that its largest loading is positive (a stable picture
    for the same data). Pixels with any non-finite band get NaN scores.
    """
    with _one_blas_thread():
        return _pca_scores(cube, mask, n)


def _pca_scores(cube: np.ndarray, mask: np.ndarray | None, n: int) -> np.ndarray:
    cube = np.asarray(cube)
    H, W, B = cube.shape
    flat = cube.reshape(-1, B)
    finite = finite_rows(flat)
    fit = finite if mask is None else finite & np.asarray(mask, dtype=bool).ravel()
    idx = np.flatnonzero(fit)
    out = np.full((H * W, n), np.nan, np.float32)
    if idx.size < 2:
        return out.reshape(H, W, n)
    idx = _sample(idx, max(2000, _MAX_SAMPLES // max(B, 1)))
    X = flat[idx].astype(np.float64)
    mean = X.mean(axis=0)
    X -= mean
    # eigen-decomposition of the B x B covariance: cheap for B in the hundreds
    cov = X.T @ X / max(len(X) - 1, 1)
    w, V = np.linalg.eigh(cov)
    V = V[:, np.argsort(w)[::-1][:n]]
    signs = np.sign(V[np.argmax(np.abs(V), axis=0), np.arange(V.shape[1])])
    V = V * np.where(signs == 0, 1.0, signs)
    k = V.shape[1]
    # one BLAS matmul over the finite pixels (the others stay NaN); subtracting the projected
    # mean afterwards avoids a centred copy of the whole cube
    Vf = np.ascontiguousarray(V.astype(np.float32))
    rows = np.flatnonzero(finite)
    proj_mean = mean.astype(np.float32) @ Vf
    for a in range(0, len(rows), 1 << 16):  # chunks: no copy of all finite rows (0.8 GB at 4K)
        r = rows[a : a + (1 << 16)]
        # a run of consecutive rows (a cube kept at its hits is all finite) is read as a view, not
        # gathered: the same (m, B) values into the same product, without the copy
        sel = slice(int(r[0]), int(r[-1]) + 1) if int(r[-1]) - int(r[0]) == len(r) - 1 else r
        sub = flat[sel]
        sub32 = sub if sub.dtype == np.float32 else sub.astype(np.float32)
        out[sel, :k] = sub32 @ Vf - proj_mean
    if k < n:
        out[finite, k:] = 0.0
    return out.reshape(H, W, n)


@dataclass(frozen=True)
class PcaBasis:
    """A fitted PCA false colour: ``mean`` (B,), ``components`` (B, 3), ``limits`` per channel.
    Rendering another cube of the same camera with it (e.g. the registered cube with the raw
    cube's basis) gives the same colour to the same spectrum."""

    mean: np.ndarray
    components: np.ndarray
    limits: tuple[tuple[float, float], ...]

    def scores(self, cube: np.ndarray) -> np.ndarray:
        """(H, W, B) -> (H, W, 3) float32 scores; NaN where any band is not finite."""
        H, W, B = cube.shape
        flat = np.asarray(cube).reshape(-1, B)
        flat32 = flat if flat.dtype == np.float32 else flat.astype(np.float32)
        V = self.components.astype(np.float32)
        out = flat32 @ V - (self.mean.astype(np.float32) @ V)
        if flat.dtype.kind == "f":
            out[~finite_rows(flat)] = np.nan
        return out.reshape(H, W, V.shape[1])


def fit_pca(cube: np.ndarray, mask: np.ndarray | None = None,
            percentiles: tuple[float, float] = (1, 99)) -> PcaBasis | None:
    """The PCA false colour of ``cube`` (H, W, B) as :func:`pca_false_colour` draws it; None
    when fewer than two pixels are finite."""
    cube = np.asarray(cube)
    B = cube.shape[2]
    flat = cube.reshape(-1, B)
    finite = finite_rows(flat)
    fit = finite if mask is None else finite & np.asarray(mask, dtype=bool).ravel()
    idx = np.flatnonzero(fit)
    if idx.size < 2:
        return None
    idx = _sample(idx, max(2000, _MAX_SAMPLES // max(B, 1)))
    X = flat[idx].astype(np.float64)
    mean = X.mean(axis=0)
    Xc = X - mean
    w, V = np.linalg.eigh(Xc.T @ Xc / max(len(Xc) - 1, 1))
    V = V[:, np.argsort(w)[::-1][:3]]
    signs = np.sign(V[np.argmax(np.abs(V), axis=0), np.arange(V.shape[1])])
    V = V * np.where(signs == 0, 1.0, signs)
    if V.shape[1] < 3:
        V = np.hstack([V, np.zeros((B, 3 - V.shape[1]))])
    basis = PcaBasis(mean, V, ((0.0, 1.0),) * 3)
    sc = basis.scores(cube)
    limits = tuple(auto_limits(sc[:, :, c], percentiles, mask) for c in range(3))
    return PcaBasis(mean, V, limits)


def pca_false_colour(cube: np.ndarray, mask: np.ndarray | None = None,
                     percentiles: tuple[float, float] = (1, 99), basis: PcaBasis | None = None) -> np.ndarray:
    """Cube (H, W, B) -> (H, W, 3) uint8: PC1 red, PC2 green, PC3 blue, each percentile-stretched;
    with ``basis``, that basis and its limits (see :class:`PcaBasis`).

    NaN pixels (any band non-finite) are drawn in :data:`BACKGROUND_RGB`.
    """
    if basis is not None and basis.mean.shape[0] == cube.shape[2]:
        return _stretch_channels(basis.scores(cube), percentiles, mask, basis.limits)
    scores = pca_scores(cube, mask, 3)
    return _stretch_channels(scores, percentiles, mask)


def _stretch_channels(img: np.ndarray, percentiles: tuple[float, float], mask: np.ndarray | None,
                      limits: Sequence[tuple[float, float]] | None = None) -> np.ndarray:
    """(H, W, 3) -> uint8 with each channel stretched on its own; NaN pixels -> background."""
    chans = []
    nan_any = None
    for c in range(3):
        lo, hi = limits[c] if limits is not None else auto_limits(img[:, :, c], percentiles, mask)
        u8, nan = _normalise_u8(img[:, :, c], lo, hi)
        chans.append(u8)
        if nan is not None:
            nan_any = nan if nan_any is None else nan_any | nan
    out = np.dstack(chans)
    if nan_any is not None:
        _paint_background(out, nan_any)
    return out


# ---------------------------------------------------------------------- the entry point
def shows_as_rgb(channels: int, modality: str | None = None) -> bool:
    """Whether :func:`to_rgb8` draws an image of ``channels`` bands as RGB when no ``bands`` are
    chosen (otherwise: a colour map for one band, PCA false colour for a cube).

    Three bands are RGB for every modality, a hyperspectral one too: such a "cube" is a camera's
    own 3-band (8-bit) rendering, and its registered version (float32, NaN outside) has the same
    three bands; a PCA of three bands only rotates their colours into an untrue picture (a green
    background). Four bands are RGBA for a colour camera; cubes of many bands stay PCA.
    """
    return channels == 3 or (channels == 4 and _modality.is_colour(modality))


def to_rgb8(img: np.ndarray, modality: str | None = None, cmap: str | None = None,
            limits: tuple[float, float] | None = None, percentiles: tuple[float, float] = (1, 99),
            bands: tuple[int, int, int] | None = None, mask: np.ndarray | None = None,
            pca: PcaBasis | None = None) -> np.ndarray:
    """Render any image for display: (H, W) or (H, W, C) -> (H, W, 3) uint8 RGB.

    * single band: colour map ``cmap`` (default by ``modality``, see :data:`DEFAULT_CMAPS`),
      limits ``limits`` or the ``percentiles`` of the finite pixels; for modality 'depth',
      values <= 0 are "no measurement" and drawn like NaN;
    * three bands (and ``bands`` not given), any modality: RGB; uint8 shown as it is, other
      dtypes stretched with one pair of limits for all channels (keeps hues);
    * four bands with modality 'rgb': RGBA, alpha dropped (see :func:`shows_as_rgb`);
    * other band counts: PCA false colour (fitted here, or ``pca`` fitted on another cube of the
      same camera by :func:`fit_pca`), or ``bands=(r, g, b)`` band indices, each stretched.

    ``mask`` (H, W) bool selects the pixels the statistics are taken from (e.g. the object);
    every pixel is still drawn. NaN pixels are drawn in :data:`BACKGROUND_RGB`.
    """
    from ..registration.hits import HitImage

    if isinstance(img, HitImage):  # render the hits only (statistics are of finite pixels anyway)
        sub = np.asarray(mask, dtype=bool).reshape(-1)[img.index][:, None] if mask is not None else None
        vals = img.values[:, None, :] if img.ndim == 3 else img.values
        rgb = to_rgb8(vals, modality, cmap, limits, percentiles, bands, sub, pca)  # the raw cube's basis too
        out = _background(img.shape[0], img.shape[1]).reshape(-1, 3)
        out[img.index] = rgb.reshape(-1, 3)
        return out.reshape(img.shape[0], img.shape[1], 3)
    a = np.asarray(img)
    mod = _modality.get(modality)
    if a.ndim == 3 and a.shape[2] == 1:
        a = a[:, :, 0]
    if a.ndim == 2:
        if mod.zero_is_missing:
            # depth 0 (or negative) means "no measurement", as in Recording.depth_m
            a = a.astype(np.float32)
            with np.errstate(invalid="ignore"):
                a[~(a > 0)] = np.nan
        name = cmap or mod.cmap
        return colorize(a, name, limits, percentiles, mask)
    if a.ndim != 3:
        raise ValueError(f"expected an (H, W) or (H, W, C) image, got shape {a.shape}")
    C = a.shape[2]
    if bands is not None:
        b = [int(i) for i in bands]
        if len(b) != 3 or min(b) < -C or max(b) >= C:
            raise ValueError(f"bands must be three indices into {C} bands, got {bands}")
        sub = a[:, :, b]
        return _stretch_channels(sub, percentiles, mask, None if limits is None else [limits] * 3)
    if shows_as_rgb(C, mod.name):
        if C == 4:
            a = a[:, :, :3]  # RGBA: alpha dropped
        if a.dtype == np.uint8 and limits is None:
            return np.ascontiguousarray(a)
        lo, hi = limits if limits is not None else auto_limits(a, percentiles, mask)
        u8, nan = _normalise_u8(a, lo, hi)
        if nan is not None:
            _paint_background(u8, nan)
        return u8
    if C == 2:
        # no natural colour for two bands: show the first, as a single band
        return colorize(a[:, :, 0], cmap or "gray", limits, percentiles, mask)
    return pca_false_colour(a, mask, percentiles, pca)


# ---------------------------------------------------------------------- overlays and comparisons
def overlay(base_rgb8: np.ndarray, codes: np.ndarray, colours: Mapping[int, tuple[int, int, int]],
            opacity: float = 0.5) -> np.ndarray:
    """Tint ``base_rgb8`` (H, W, 3) uint8 where ``codes`` (H, W) uint8 has a code in ``colours``.

    Codes missing from ``colours`` (e.g. P1, P6) are left untouched. Returns a new array.
    """
    base = np.asarray(base_rgb8, dtype=np.uint8)
    codes = np.asarray(codes)
    if codes.shape != base.shape[:2]:
        raise ValueError(f"codes {codes.shape} and image {base.shape[:2]} differ in size")
    lut = np.zeros((256, 3), np.uint8)
    has = np.zeros(256, bool)
    for c, rgb in colours.items():
        if rgb is not None:
            lut[int(c)] = rgb
            has[int(c)] = True
    c8 = codes.astype(np.uint8, copy=False)
    sel = has[c8]
    op = float(np.clip(opacity, 0.0, 1.0))
    out = base.copy()
    if sel.any():
        # whole-image blend + masked copy: faster than fancy indexing on 4K frames
        tint = cv2.addWeighted(base, 1.0 - op, lut[c8], op, 0.0)
        cv2.copyTo(tint, sel.view(np.uint8), out)
    return out


def mosaic(images: Sequence[np.ndarray], tile: int) -> np.ndarray:
    """Tile alternating images as in the paper's mosaic figure: tile (i, j) shows image (i + j) mod n.

    ``images`` all (H, W, 3) uint8 of one size; ``tile`` the tile edge in pixels. Tile (i, j)
    covers rows ``i*tile .. (i+1)*tile - 1`` and columns ``j*tile .. (j+1)*tile - 1``.
    """
    if not images:
        raise ValueError("mosaic needs at least one image")
    shape = images[0].shape
    for im in images:
        if im.shape != shape:
            raise ValueError(f"mosaic images differ in size: {im.shape} vs {shape}")
    tile = max(1, int(tile))
    n = len(images)
    H, W = shape[:2]
    out = np.array(images[0], copy=True)
    if n == 1:
        return out
    # copy tile by tile (slices, no per-pixel masks): a few thousand views even on 4K
    for i, r0 in enumerate(range(0, H, tile)):
        for j, c0 in enumerate(range(0, W, tile)):
            k = (i + j) % n
            if k:
                out[r0:r0 + tile, c0:c0 + tile] = images[k][r0:r0 + tile, c0:c0 + tile]
    return out


def checkerboard(a: np.ndarray, b: np.ndarray, tile: int) -> np.ndarray:
    """Two images in a checkerboard of ``tile``-pixel squares (``a`` at the top-left)."""
    return mosaic([a, b], tile)


def shown_colours(composed_rgb8: np.ndarray, codes: np.ndarray, wanted, step: int = 4) -> dict[int, tuple[int, int, int]]:
    """The colour each code in ``wanted`` shows as in ``composed_rgb8`` (H, W, 3) uint8 (an
    :func:`overlay` of ``codes`` (H, W)): the median over its pixels (every ``step``-th row and
    column). A legend swatch in this colour matches the map: a tint at partial opacity over a dark
    picture is darker than the pure colour (orange reads brown). Codes without pixels are left out."""
    full_img, full_codes = np.asarray(composed_rgb8), np.asarray(codes)
    img = full_img[::step, ::step].reshape(-1, 3)
    c = full_codes[::step, ::step].ravel()
    out = {}
    for code in wanted:
        sel = c == int(code)
        px = img[sel]
        if len(px) < 50:  # a rare code: all its pixels
            px = full_img[full_codes == int(code)]
        if len(px):
            out[int(code)] = tuple(int(v) for v in np.median(px, axis=0))
    return out


def blend(a: np.ndarray, b: np.ndarray, alpha: float) -> np.ndarray:
    """``(1 - alpha) * a + alpha * b`` for uint8 images of one shape."""
    if a.shape != b.shape:
        raise ValueError(f"blend images differ in size: {a.shape} vs {b.shape}")
    alpha = float(np.clip(alpha, 0.0, 1.0))
    return cv2.addWeighted(np.asarray(a, np.uint8), 1.0 - alpha, np.asarray(b, np.uint8), alpha, 0.0)


def default_tile(shape: tuple[int, ...]) -> int:
    """A mosaic tile size that shows about 8 tiles along the shorter side (at least 8 px)."""
    return max(8, int(round(min(shape[:2]) / 8)))
