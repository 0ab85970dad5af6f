"""Bilinear sampling of raw source images at projected positions (any dtype, any band count,
pixel- or band-interleaved cubes without a copy), threaded for big band-sequential cubes."""

from __future__ import annotations

from typing import Callable

import numpy as np

from ..geometry.raycast import RAY_CHUNK
from ..progress import Reporter, ensure_reporter

#: Samples of a band-sequential cube gathered and written together: their (C, rows) float32
#: block (3.3 MB for 204 bands) is still in cache when it is written out transposed (less CPU than
#: 64 MB blocks; the same values).
_BAND_ROWS = 1 << 12


def _sample_chunk_rows(n_channels: int) -> int:
    # ~64 MB of float32 output per chunk
    return int(min(RAY_CHUNK, max(1 << 14, (64 << 20) // (4 * max(1, n_channels)))))


#: Threads that sample a band-sequential cube (``sample_bilinear``); 1 = the calling thread only.
#: None: the cores (at most 2) when there are at least :data:`_THREAD_MIN_VALUES` values to sample.
SAMPLE_THREADS: int | None = None
_THREAD_MIN_VALUES = 1 << 24


def _sample_threads(n: int, C: int) -> int:
    import os

    if SAMPLE_THREADS is not None:
        return max(1, int(SAMPLE_THREADS))
    return min(2, os.cpu_count() or 1) if n * C >= _THREAD_MIN_VALUES else 1


def sample_bilinear(image: np.ndarray, uv: np.ndarray, progress: Reporter | None = None, *,
                    out: np.ndarray | None = None, rows: np.ndarray | None = None,
                    done: Callable[[int], None] | None = None, threads: int | None = None) -> np.ndarray:
    """Bilinear samples of ``image`` (h, w) or (h, w, C), any dtype, at pixel positions ``uv``
    (N, 2) (pixel centres at integers) -> (N,) or (N, C) float32. NaN rows of ``uv`` give NaN.

    With ``out`` (M, C) float32 (its contents need not be set) and ``rows`` (N,), sample i is
    written to ``out[rows[i]]`` instead, every other row of ``out`` (not in ``rows``, or with NaN
    ``uv``) is set to NaN, and ``out`` is returned: no NaN pass over rows that get a sample.

    Positions in the half-pixel border of the image take the edge pixel's value (clamped).
    Exact (no fixed-point weights as in ``cv2.remap``, which also handles at most 4 channels).
    Pixel-interleaved images with a few channels are gathered directly; with many channels
    (BIP hyperspectral cubes) a sparse (N x h*w) interpolation matrix multiplies the (h*w, C)
    cube, reading each pixel's spectrum contiguously; band-sequential cubes (ENVI BSQ loads as a
    (h, w, C) view of a (C, h, w) array) are gathered a few bands at a time so that each band
    stays in cache. No copy of the cube is made in either layout.

    ``done(k)``, with ``out`` and ascending ``rows``: called on this thread whenever the first
    ``k`` rows of ``out`` are final (a reader may take them while the rest is sampled).
    ``threads``: sampling threads for a band-sequential cube (default :func:`_sample_threads`).
    """
    progress = ensure_reporter(progress)
    img = np.asarray(image)
    h, w = img.shape[:2]
    if img.ndim > 3:
        img = img.reshape(h, w, -1)
    C = 1 if img.ndim == 2 else img.shape[2]
    band_first = C > 1 and img.transpose(2, 0, 1).flags.c_contiguous and not img.flags.c_contiguous
    if band_first:
        planes = img.transpose(2, 0, 1).reshape(C, h * w)
    else:
        flat = np.ascontiguousarray(img).reshape(h * w, C)
        if C > 4 and flat.dtype != np.float32:
            flat = flat.astype(np.float32)  # once, not per chunk (scipy would convert the whole cube)
    uv = np.asarray(uv)
    n = len(uv)
    squeeze = out is None and C == 1
    if out is None:
        out = np.full((n, C), np.nan, dtype=np.float32)
        rows_all = np.arange(n)
    else:
        out = out.reshape(len(out), C)
        rows_all = np.asarray(rows)
    ok = np.flatnonzero(np.isfinite(uv).all(axis=1))
    if rows is not None:
        unsampled = np.ones(len(out), dtype=bool)
        unsampled[rows_all[ok]] = False
        out[unsampled] = np.nan
    step = _sample_chunk_rows(C)
    du = 1 if w > 1 else 0
    dv = w if h > 1 else 0
    n_threads = (threads or _sample_threads(len(ok), C)) if band_first else 1
    ascending = rows is not None and (len(rows_all) < 2 or bool(np.all(rows_all[1:] > rows_all[:-1])))
    if done is not None and band_first:
        step = min(step, 4 * _BAND_ROWS)  # a reader waits for at most ~13 MB of a 204-band cube

    def report(a: int) -> None:  # chunk ``a`` (and every one before it) is written
        if done is not None and ascending:
            end = min(a + step, len(ok))
            done(len(out) if end == len(ok) else int(rows_all[ok[end]]))
    if n_threads > 1:  # chunks small enough that every thread gets several (load balance)
        per = -(-len(ok) // (4 * n_threads))
        step = min(step, max(_BAND_ROWS, -(-per // _BAND_ROWS) * _BAND_ROWS))

    def chunk(a: int) -> None:
        sel = ok[a : a + step]
        u = np.clip(uv[sel, 0].astype(np.float64), 0, w - 1)
        v = np.clip(uv[sel, 1].astype(np.float64), 0, h - 1)
        u0 = np.minimum(np.floor(u), max(w - 2, 0)).astype(np.int64)
        v0 = np.minimum(np.floor(v), max(h - 2, 0)).astype(np.int64)
        fu = (u - u0).astype(np.float32)
        fv = (v - v0).astype(np.float32)
        i00 = v0 * w + u0
        w00, w01 = (1 - fu) * (1 - fv), fu * (1 - fv)
        w10, w11 = (1 - fu) * fv, fu * fv
        dst = rows_all[sel]
        if band_first:
            idx = np.stack([i00, i00 + du, i00 + dv, i00 + dv + du])  # (4, m)
            wts = np.stack([w00, w01, w10, w11])
            m = len(sel)
            acc = np.empty((C, min(m, _BAND_ROWS)), dtype=np.float32)
            for t0 in range(0, m, _BAND_ROWS):
                t1 = min(m, t0 + _BAND_ROWS)
                A = acc[:, : t1 - t0]
                for b0 in range(0, C, 4):
                    blk = planes[b0 : b0 + 4]  # a few bands: ~1 MB each, kept in cache for the 4 gathers
                    g = np.take(blk, idx[:, t0:t1], axis=1).astype(np.float32, copy=False)  # (nb, 4, rows)
                    np.einsum("bkm,km->bm", g, wts[:, t0:t1], out=A[b0 : b0 + 4])
                out[dst[t0:t1]] = A.T
            return
        if C <= 4:
            acc = flat[i00].astype(np.float32) * w00[:, None]
            acc += flat[i00 + du] * w01[:, None]
            acc += flat[i00 + dv] * w10[:, None]
            acc += flat[i00 + dv + du] * w11[:, None]
        else:
            import scipy.sparse as sp

            m = len(sel)
            cols = np.stack([i00, i00 + du, i00 + dv, i00 + dv + du], axis=1).ravel()
            wts = np.stack([w00, w01, w10, w11], axis=1).ravel()
            M = sp.csr_matrix((wts, cols, np.arange(0, 4 * m + 1, 4)), shape=(m, h * w))
            acc = M @ flat
        out[dst] = acc

    starts = range(0, len(ok), step)
    if n_threads <= 1:
        for a in starts:
            progress(a / max(1, len(ok)))
            chunk(a)
            report(a)
        if done is not None:
            done(len(out))
        return out[:, 0] if squeeze else out
    # band-sequential cubes: chunks in threads (numpy's take, einsum and the scatter release the
    # GIL); progress and cancellation stay on this thread; chunks write disjoint rows of ``out``
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(n_threads, thread_name_prefix="plantreg-sample") as ex:
        try:
            futures = [ex.submit(chunk, a) for a in starts]
            for a, f in zip(starts, futures):
                progress(a / max(1, len(ok)))
                f.result()
                report(a)
        except BaseException:
            ex.shutdown(wait=True, cancel_futures=True)
            raise
    if done is not None:
        done(len(out))
    return out[:, 0] if squeeze else out
