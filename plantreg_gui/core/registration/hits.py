"""Registered values stored only where the target's rays hit the object.

A registered image is NaN wherever the target ray hits no object mesh (~85-90 % of a view):
storing it dense costs H x W x bands float32 -- 6.8 GB for a 204-band cube registered into a 4K
view. :class:`HitImage` keeps only the hit pixels' values, ``values`` (M, C) float32 at the
row-major pixel indices ``index`` (M,) (sorted), and expands them to an image on demand:

* ``np.asarray(img)`` / ``img.dense()`` -- the full (H, W[, C]) float32 image, NaN elsewhere,
  exactly the array a dense registration gave (so existing code keeps working: indexing,
  ``np.isfinite``, ``.astype``, arithmetic all go through the dense array);
* ``img.block(r0, r1, c0, c1)`` -- one block (tiles for writing; None if it holds no hit);
* ``img[r, c]`` -- one pixel without expanding the image (cursor read-outs).
"""

from __future__ import annotations

from typing import Any

import numpy as np


#: Result arrays in this size range are allocated from a plain anonymous mapping (see nan_array).
_PLAIN_PAGES_BYTES = (64 << 20, 1 << 30)


def nan_array(shape: tuple[int, ...]) -> np.ndarray:
    """``np.full(shape, nan, float32)``; arrays of 64 MB .. 1 GB come from a plain anonymous ``mmap``.

    Why: numpy asks the kernel for transparent huge pages on large allocations; where the kernel
    compacts memory on demand for them (``defrag = madvise``, a common default) the first touch
    of a fresh result stalls while it assembles 2 MB pages -- several times the time with
    ordinary pages for the 300 MB of a 204-band cube registered into the 640x576 infrared view
    (figures: docs/performance.md). For multi-gigabyte results (the same cube in a 4K view:
    6.8 GB) the number of page faults dominates instead, and huge pages are the faster choice.
    """
    n = int(np.prod(shape))
    lo, hi = _PLAIN_PAGES_BYTES
    if not lo <= n * 4 <= hi:
        return np.full(shape, np.nan, dtype=np.float32)
    import mmap

    buf = mmap.mmap(-1, n * 4)
    a = np.frombuffer(buf, dtype=np.float32, count=n).reshape(shape)
    a.fill(np.nan)
    return a



class RowsReady:
    """How many leading rows of an array another thread is still filling are final: the filler
    calls :meth:`set` (and :meth:`fail` if it stops), readers :meth:`wait`."""

    def __init__(self) -> None:
        import threading

        self._n, self._failed = 0, False
        self._cv = threading.Condition()

    def set(self, n: int) -> None:
        with self._cv:
            self._n = max(self._n, int(n))
            self._cv.notify_all()

    def fail(self) -> None:
        with self._cv:
            self._failed = True
            self._cv.notify_all()

    def wait(self, n: int) -> None:
        """Return once the first ``n`` rows are final; :class:`~.errors.Cancelled` if the filler failed."""
        with self._cv:
            while self._n < n and not self._failed:
                self._cv.wait()
            if self._n < n:
                from ..errors import Cancelled

                raise Cancelled("the values were not completed")


class HitImage:
    """(H, W) or (H, W, C) float32 image that is NaN except at the pixels ``index`` (M,) sorted
    row-major indices, whose values are ``values`` (M, C) float32.

    ``ready``: while the registration still fills ``values`` (row by row, in index order), a
    :class:`RowsReady`; :meth:`block` waits for the rows it reads (a TIFF writer runs alongside
    the sampling); nothing else may read the values until then. None once complete."""

    __array_priority__ = 20
    ready: RowsReady | None = None

    def __init__(self, index: np.ndarray, values: np.ndarray, shape: tuple[int, ...]):
        index = np.asarray(index, dtype=np.int64)
        values = np.asarray(values, dtype=np.float32).reshape(len(index), -1)
        if index.size > 1 and np.any(index[1:] < index[:-1]):
            order = np.argsort(index, kind="stable")
            index, values = index[order], values[order]
        self.index, self.values = index, values
        self.shape = tuple(int(s) for s in shape)
        self.dtype = np.dtype(np.float32)

    # -- what an ndarray says about itself
    @property
    def ndim(self) -> int:
        return len(self.shape)

    @property
    def size(self) -> int:
        return int(np.prod(self.shape))

    @property
    def nbytes(self) -> int:
        """Bytes of the *dense* image (what ``np.asarray`` would allocate)."""
        return self.size * 4

    @property
    def bands(self) -> int:
        return self.values.shape[1]

    def __len__(self) -> int:
        return self.shape[0]

    def __repr__(self) -> str:
        return f"HitImage(shape={self.shape}, hits={len(self.index)})"

    # -- expansion
    def dense(self) -> np.ndarray:
        """The full image (H, W[, C]) float32, NaN where there is no hit (a new array)."""
        H, W = self.shape[:2]
        out = nan_array((H * W, self.bands))
        out[self.index] = self.values
        return out.reshape(self.shape)

    def __array__(self, dtype: Any = None, copy: Any = None) -> np.ndarray:
        a = self.dense()
        return a if dtype is None else a.astype(dtype, copy=False)

    def block(self, r0: int, r1: int, c0: int, c1: int) -> np.ndarray | None:
        """Rows r0..r1-1, columns c0..c1-1 as (r1-r0, c1-c0[, C]) float32; None if no hit lies there."""
        W = self.shape[1]
        # per row of the block, the run of hits between its first and last column (sorted index)
        starts = np.arange(r0, r1, dtype=np.int64) * W
        lo = np.searchsorted(self.index, starts + c0)
        hi = np.searchsorted(self.index, starts + c1)
        cnt = hi - lo
        total = int(cnt.sum())
        if total == 0:
            return None
        ready = self.ready  # read once: the filler sets it to None when done
        if ready is not None:
            ready.wait(int(hi[-1]))
        h, w = r1 - r0, c1 - c0
        # row by row: a row's hits are the run values[lo:hi] (sorted index), so a full row is one
        # slice copy and a partial one a small scatter -- no gather of all the block's hits and
        # 2-D scatter (the TIFF writer's tiles of a 4K cube: ~2x less GIL-holding CPU)
        out = np.empty((h, w, self.bands), dtype=np.float32)
        if total < h * w:
            out.fill(np.nan)
        for i in np.flatnonzero(cnt).tolist():
            a, b = int(lo[i]), int(hi[i])
            if b - a == w:
                out[i] = self.values[a:b]
            else:
                out[i, self.index[a:b] - (starts[i] + c0)] = self.values[a:b]
        return out if self.ndim == 3 else out[:, :, 0]

    def __getitem__(self, key: Any) -> Any:
        if isinstance(key, tuple) and len(key) >= 2 and all(isinstance(k, (int, np.integer)) for k in key[:2]):
            r, c = int(key[0]), int(key[1])
            H, W = self.shape[:2]
            if not (-H <= r < H and -W <= c < W):
                raise IndexError(f"pixel ({r}, {c}) outside {W}x{H}")
            flat = (r % H) * W + (c % W)
            i = int(np.searchsorted(self.index, flat))
            if i < len(self.index) and self.index[i] == flat:
                v = self.values[i]
            else:
                v = np.full(self.bands, np.nan, dtype=np.float32)
            v = v if self.ndim == 3 else v[0]
            return v[key[2:]] if len(key) > 2 else (v.copy() if self.ndim == 3 else v)
        return self.dense()[key]

    def __getattr__(self, name: str) -> Any:
        # anything else an ndarray offers (astype, reshape, min, ...) on the dense image
        if name.startswith("__"):
            raise AttributeError(name)
        return getattr(self.dense(), name)

    # arithmetic and comparisons through the dense image
    def _op(name: str):  # noqa: N805 - a method factory
        def f(self, *other):
            return getattr(self.dense(), name)(*other)
        f.__name__ = name
        return f

    for _n in ("__add__", "__radd__", "__sub__", "__rsub__", "__mul__", "__rmul__", "__truediv__",
               "__rtruediv__", "__neg__", "__lt__", "__le__", "__gt__", "__ge__", "__eq__", "__ne__", "__pow__"):
        locals()[_n] = _op(_n)
    del _n, _op
    __hash__ = None  # type: ignore[assignment]


def as_hit_image(a: Any) -> HitImage | None:
    return a if isinstance(a, HitImage) else None


def rows_at(img: Any, flat: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Where a registered image -- an (H, W[, C]) array or a :class:`HitImage` -- keeps the
    values of the row-major pixels ``flat`` (n,): ``(store, rows, hit)`` with ``store`` (N, C) the
    array holding them (a view of a dense image; a HitImage's ``values``), ``hit`` (n,) bool the
    pixels it has a value for and ``rows`` (hit.sum(),) their rows in ``store``. Reading
    ``store[rows, b0:b1]`` then reads only those pixels and bands (chunked statistics of a cube)."""
    flat = np.asarray(flat, dtype=np.int64).ravel()
    if isinstance(img, HitImage):
        if not len(img.index):
            return img.values, np.zeros(0, np.int64), np.zeros(len(flat), bool)
        pos = np.minimum(np.searchsorted(img.index, flat), len(img.index) - 1)
        hit = img.index[pos] == flat
        return img.values, pos[hit], hit
    a = np.asarray(img)
    return a.reshape(a.shape[0] * a.shape[1], -1), flat, np.ones(len(flat), bool)


def values_at(img: Any, flat: np.ndarray) -> np.ndarray:
    """(n, C) float32 values of a registered image -- an (H, W[, C]) array or a
    :class:`HitImage` -- at the row-major pixel indices ``flat`` (n,); NaN where a HitImage has
    no hit. Only those pixels are read: a HitImage is never expanded. When ``flat`` is a run of
    the HitImage's own hits (the point cloud's rows), its values are returned as a read-only view
    (no search, no copy: 45 MB per paper-sized recording)."""
    if isinstance(img, HitImage):
        n = len(flat)
        if 0 < n <= len(img.index):
            p = int(np.searchsorted(img.index, flat[0]))
            if p + n <= len(img.index) and np.array_equal(img.index[p : p + n], flat):
                view = img.values[p : p + n]
                view.flags.writeable = False
                return view
    store, rows, hit = rows_at(img, flat)
    if hit.all():
        return store[rows].astype(np.float32, copy=False)
    out = np.full((len(hit), store.shape[1]), np.nan, dtype=np.float32)
    out[hit] = store[rows]
    return out


__all__ = ["HitImage", "nan_array", "as_hit_image", "rows_at", "values_at"]
