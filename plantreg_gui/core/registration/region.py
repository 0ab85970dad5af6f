"""Statistics of a registration over a region of the target image (the workspace's region tool).

A region is a rectangle or a polygon in target pixel coordinates. For one source camera it
reports how the region's pixels divide into cases (P1, P2, P3.1, ...) and summarises the
source's registered values over the *trusted* pixels: P1 (legitimate) and not flagged mixed
(footprint across a silhouette, core/registration/mixed.py) - e.g. the mean leaf temperature. For a cube the
mean spectrum over those pixels, with the band centres in nm when the rig gives them.
:func:`stats_csv` writes it as a tidy CSV (one value per row). Qt-free; the view only draws.
"""

from __future__ import annotations

import csv
import io
from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np

from .cases import Case
from ..errors import InputError
from .hits import rows_at
from ..progress import ProgressCallback, Reporter, ensure_reporter


def region_mask(shape: tuple[int, int], rect: Sequence[float] | None = None,
                polygon: Sequence[Sequence[float]] | None = None) -> np.ndarray:
    """(H, W) bool mask of a region of an image of ``shape`` (H, W).

    ``rect`` (x0, y0, x1, y1) in pixel coordinates (x = column; either corner order; a pixel is
    inside when its centre is: the pixel (r, c) covers [c, c+1) x [r, r+1)); ``polygon`` (N, 2)
    (x, y) vertices in pixel coordinates, N >= 3 (pixels whose centre lies inside). Clipped to
    the image."""
    H, W = int(shape[0]), int(shape[1])
    mask = np.zeros((H, W), bool)
    if rect is not None:
        x0, y0, x1, y1 = (float(v) for v in rect)
        x0, x1 = sorted((x0, x1))
        y0, y1 = sorted((y0, y1))
        c0, c1 = int(np.clip(np.ceil(x0 - 0.5), 0, W)), int(np.clip(np.ceil(x1 - 0.5), 0, W))
        r0, r1 = int(np.clip(np.ceil(y0 - 0.5), 0, H)), int(np.clip(np.ceil(y1 - 0.5), 0, H))
        mask[r0:r1, c0:c1] = True
        return mask
    if polygon is not None:
        p = np.asarray(polygon, dtype=np.float64).reshape(-1, 2)
        if len(p) < 3:
            raise InputError("a polygon region needs at least 3 corners")
        # exactly the pixels whose centre is inside (OpenCV's fillPoly also fills pixels the
        # rasterised edges touch); only the polygon's bounding box is tested
        from matplotlib.path import Path as _Path

        c0, r0 = (int(np.clip(np.floor(v), 0, n)) for v, n in zip(p.min(axis=0), (W, H)))
        c1, r1 = (int(np.clip(np.ceil(v) + 1, 0, n)) for v, n in zip(p.max(axis=0), (W, H)))
        rr, cc = np.mgrid[r0:r1, c0:c1]
        centres = np.column_stack([cc.ravel() + 0.5, rr.ravel() + 0.5])
        mask[r0:r1, c0:c1] = _Path(p).contains_points(centres).reshape(rr.shape)
        return mask
    raise InputError("a region needs a rectangle or a polygon")


@dataclass
class RegionStats:
    """Statistics of one source over a region (see :func:`region_stats`).

    ``cases`` short case label -> (pixels, percent of the region); ``trusted`` number of P1 pixels
    not flagged mixed with a finite value (what the value statistics use); ``mean``, ``median``,
    ``std`` (B,) over the trusted pixels, per band (B = 1 for single-band images); ``wavelengths``
    (B,) nm or None; ``unit`` of the values."""

    source: str
    pixels: int
    cases: dict[str, tuple[int, float]]
    mixed: int
    trusted: int
    mean: np.ndarray
    median: np.ndarray
    std: np.ndarray
    wavelengths: np.ndarray | None = None
    unit: str = ""
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def bands(self) -> int:
        return int(self.mean.size)


CHUNK = 1 << 22  # values read at a time (16 MB of float32): a 4K cube's region is never copied whole


def region_stats(result: Any, mask: np.ndarray, source: str, wavelengths: np.ndarray | None = None,
                 unit: str = "", progress: Reporter | ProgressCallback | None = None) -> RegionStats:
    """Statistics of ``source`` over the ``mask`` (H, W) bool pixels of ``result`` (a
    :class:`~.register.RegistrationResult`): case counts of its case map (the target itself has
    none: all its pixels count as P1), and mean / median / std per band of its registered values
    over the P1 pixels not flagged mixed whose every band is finite (NaN when there are none).

    Only the selected pixels are read, :data:`CHUNK` values at a time (a whole 4K view of a
    204-band cube would be 1.8 GB at once): first whole pixels (which have all bands finite),
    then a few bands over all trusted pixels (exact medians). ``progress`` is called between
    chunks; a cancelled :class:`~.progress.Reporter` raises ``Cancelled`` there."""
    rep = ensure_reporter(progress)
    mask = np.asarray(mask, bool)
    if mask.shape != tuple(result.shape):
        raise InputError(f"region of shape {mask.shape} does not match the target image {tuple(result.shape)}")
    if source not in result.registered:
        raise InputError(f"no registered image of camera '{source}'")
    rep(0.0, f"cases of {source}")
    n = int(mask.sum())
    codes = result.cases.get(source)
    if codes is None:  # the target: its own values, P1 wherever the object was hit
        obj = np.isfinite(np.asarray(result.points_rig)[..., 2])
        codes = np.where(obj, int(Case.P1), int(Case.BACKGROUND)).astype(np.uint8)
    cm = np.asarray(codes, np.uint8)[mask]
    counts = np.bincount(cm, minlength=256)
    order = sorted(Case, key=lambda c: (c == Case.BACKGROUND, int(c)))  # the object's cases first, P6 last
    cases = {c.short: (int(counts[c]), 100.0 * counts[c] / n if n else 0.0) for c in order}
    mixed_map = (getattr(result, "mixed", None) or {}).get(source)
    mixed = np.asarray(mixed_map, bool)[mask] if mixed_map is not None else np.zeros(n, bool)
    p1 = cm == Case.P1
    cand = np.flatnonzero(mask.ravel())[p1 & ~mixed]  # only these pixels' values are read
    store, rows, _ = rows_at(result.registered[source], cand)  # pixels without a value are not finite
    B = store.shape[1]
    # pass 1, whole pixels (contiguous rows): those with every band finite
    step = max(1, CHUNK // B)
    keep = np.empty(len(rows), bool)
    for i in range(0, len(rows), step):
        rep(0.05 + 0.25 * i / max(len(rows), 1), f"finite values of {source}")
        keep[i:i + step] = np.isfinite(store[rows[i:i + step]]).all(axis=1)
    rows = rows[keep]
    m = len(rows)
    mean, median, std = (np.full(B, np.nan) for _ in range(3))
    # pass 2, a few bands at a time over every trusted pixel: (k, m) contiguous float32, reduced
    # along memory order (much faster than along a strided axis)
    k = max(1, CHUNK // max(m, 1))
    for b0 in range(0, B if m else 0, k):
        rep(0.3 + 0.7 * b0 / B, f"statistics of {source}" + (f" (band {b0 + 1} of {B})" if B > 1 else ""))
        v = np.ascontiguousarray(store[rows, b0:b0 + k].T, dtype=np.float32)
        mean[b0:b0 + k] = v.mean(axis=1, dtype=np.float64)
        std[b0:b0 + k] = v.std(axis=1, dtype=np.float64)
        median[b0:b0 + k] = np.median(v, axis=1, overwrite_input=True)
    rep(1.0, f"statistics of {source}")
    wl = None if wavelengths is None else np.asarray(wavelengths, np.float64).ravel()
    if wl is not None and wl.size != B:
        wl = None
    return RegionStats(source, n, cases, int((p1 & mixed).sum()), m, mean, median, std, wl, unit)


def stats_csv(stats: Sequence[RegionStats], region: str = "") -> str:
    """The statistics as a tidy CSV (one value per row): columns ``region, source, statistic,
    case, band, wavelength_nm, value, unit``. Case rows: ``pixels`` and ``percent`` per case;
    value rows: ``mean``, ``median``, ``std`` over ``P1 not mixed`` per band (band empty for
    single-band images), and ``pixels`` of that selection."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["region", "source", "statistic", "case", "band", "wavelength_nm", "value", "unit"])
    for s in stats:
        for case, (cnt, pct) in s.cases.items():
            w.writerow([region, s.source, "pixels", case, "", "", cnt, ""])
            w.writerow([region, s.source, "percent", case, "", "", f"{pct:.4f}", "%"])
        w.writerow([region, s.source, "pixels", "P1 mixed", "", "", s.mixed, ""])
        w.writerow([region, s.source, "pixels", "P1 not mixed", "", "", s.trusted, ""])
        for stat in ("mean", "median", "std"):
            arr = getattr(s, stat)
            for b in range(s.bands):
                band = "" if s.bands == 1 else b
                wl = "" if s.wavelengths is None else f"{s.wavelengths[b]:g}"
                val = "" if not np.isfinite(arr[b]) else f"{arr[b]:.6g}"
                w.writerow([region, s.source, stat, "P1 not mixed", band, wl, val, s.unit])
    return buf.getvalue()


__all__ = ["CHUNK", "region_mask", "RegionStats", "region_stats", "stats_csv"]
