"""Registered images (``OUT/registered/<camera>.tif``) encoded off the main thread: the writer of
one TIFF, its encoding during the registration (:class:`EarlyTiffs`) and the background thread
the export waits for (:class:`Background`); used by :mod:`.export`."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any, Callable

import numpy as np

from ..io.imageio import TIFF_CODEC_DEFAULT, dense_tiles, tiff_tile_edge, write_tiff_tiled
from ..io.paths import temp_beside
from ..registration.hits import HitImage
from ..validate import file_stem
from .summary import bands as _bands


def write_registered_tiff(path: Path, reg: Any, codec: str, stop: Any = None) -> float:
    """One ``registered/<camera>.tif`` (tiled, compressed, empty tiles encoded once); seconds taken.
    ``stop`` (a threading.Event): set, the writing ends with :class:`~.errors.Cancelled` (no file)."""
    t0 = time.perf_counter()
    if isinstance(reg, HitImage):  # expanded tile by tile, never as a whole
        shape, tile_of = reg.shape, _hit_tiles(reg)
    else:
        reg = np.asarray(reg, dtype=np.float32)
        shape, tile_of = reg.shape, dense_tiles(reg)
    if stop is not None:
        inner = tile_of

        def tile_of(r0: int, r1: int, c0: int, c1: int):  # noqa: F811 - the same with a stop check
            if stop.is_set():
                from ..errors import Cancelled

                raise Cancelled("stopped")
            return inner(r0, r1, c0, c1)
    write_tiff_tiled(path, shape, np.float32, tile_of, codec=codec)
    return time.perf_counter() - t0


class EarlyTiffs:
    """``registered/<camera>.tif`` files encoded in a background thread while the registration
    still runs, as a context: pass it as ``on_image`` to :meth:`~.register.Registrar.register`
    and as ``early`` to :func:`write_outputs`, which moves the files into its folder.

    Why: registering into a 4K view keeps one core busy for seconds while the other idles, and
    then the export is bound by deflating the 204-band cube's ~0.8 GB of hit values on both
    cores; sources are registered cube first (``register``), so its TIFF is encoded while the
    other sources are registered. The files are the ones :func:`write_outputs` would write (the
    same function, from the same arrays, which must not change in between). They are staged in a
    hidden ``.<out>.XXXX.part`` folder beside ``out``; leaving the context (also by an error)
    stops the encoding and removes that folder.
    """

    def __init__(self, out: str | Path, codec: str = TIFF_CODEC_DEFAULT):
        self.out, self.codec = Path(out), codec
        self._jobs: dict[str, tuple[Any, Any, Path]] = {}  # camera -> (image, future, staged path)

    def __enter__(self) -> "EarlyTiffs":
        import threading
        from concurrent.futures import ThreadPoolExecutor

        from .. import signals

        with signals.deferred():  # a signal here would leave the folder without __exit__ to remove it
            self._dir = temp_beside(self.out, folder=True)
            self._stop = threading.Event()
            self._pool = ThreadPoolExecutor(1, thread_name_prefix="plantreg-early")
        return self

    def __call__(self, cam: str, image: Any) -> None:
        path = self._dir / f"{file_stem(cam)}.tif"  # staged: moved to its place in OUT by take()
        if cam not in self._jobs:
            self._jobs[cam] = (image, self._pool.submit(write_registered_tiff, path, image, self.codec, self._stop),
                               path)

    def has(self, cam: str, image: Any, codec: str) -> bool:
        """Whether ``cam``'s TIFF of this very ``image`` in ``codec`` is (being) encoded here."""
        return cam in self._jobs and self._jobs[cam][0] is image and codec == self.codec

    def take(self, cam: str, dest: Path) -> float:
        """Wait for ``cam``'s TIFF (its error is raised here) and move it to ``dest``; seconds encoding took."""
        import os

        from ..io.imageio import _renamed

        _image, fut, path = self._jobs.pop(cam)
        try:
            seconds = fut.result()
        except OSError as e:  # named as the file the user gets (write_outputs names it under OUT)
            raise _renamed(e, path, dest) from None
        dest.parent.mkdir(parents=True, exist_ok=True)
        os.replace(path, dest)
        return seconds

    def __exit__(self, *exc) -> None:
        import shutil

        self._stop.set()
        try:
            self._pool.shutdown(wait=True, cancel_futures=True)
        finally:
            # a terminating signal may interrupt the wait above (leaving by success: nothing is
            # unwinding yet), which left the folder behind; the writer was told to stop, so wait for
            # it again (later signals are ignored while this one unwinds), then remove the folder
            try:
                self._pool.shutdown(wait=True)
            finally:
                shutil.rmtree(self._dir, ignore_errors=True)


def _hit_tiles(reg: HitImage) -> Callable[[int, int, int, int], np.ndarray | None]:
    """``tile_of`` for :func:`~.imageio.write_tiff_tiled` of a HitImage: its blocks, and None at
    once for a block without a hit, from an occupancy grid of the writer's tile size made once.
    Why: ~90 % of a 4K view's 32,400 tiles hold no hit, and finding that out by searching the
    hits tile by tile (``HitImage.block``) holds the GIL for long; the grid is quick.
    Any block geometry is answered correctly (every grid cell it touches is looked at)."""
    H, W = reg.shape[:2]
    g = tiff_tile_edge(_bands(reg), 4)  # the writer's tile edge for float32: one cell per tile
    rows, cols = np.divmod(np.asarray(reg.index), W)
    occupied = np.zeros((-(-H // g), -(-W // g)), bool)
    occupied[rows // g, cols // g] = True

    def tile_of(r0: int, r1: int, c0: int, c1: int) -> np.ndarray | None:
        if not occupied[r0 // g : (r1 - 1) // g + 1, c0 // g : (c1 - 1) // g + 1].any():
            return None
        return reg.block(r0, r1, c0, c1)
    return tile_of


class Background:
    """One background thread for output files, as a context: leaving it (also by an exception
    or a cancel) cancels what has not started and waits for what runs, so that no file is
    written into a folder that is being removed."""

    def __enter__(self) -> "Background":
        from concurrent.futures import ThreadPoolExecutor

        self._pool = ThreadPoolExecutor(1, thread_name_prefix="plantreg-write")
        self._futures: list = []
        return self

    def submit(self, fn, *args) -> None:
        self._futures.append(self._pool.submit(fn, *args))

    def pending(self) -> bool:
        return bool(self._futures)

    def wait(self) -> float:
        """Wait for every submitted call (in order; the first error is raised); sum of their results."""
        futures, self._futures = self._futures, []
        return float(sum(f.result() for f in futures))

    def __exit__(self, *exc) -> None:
        self._pool.shutdown(wait=True, cancel_futures=True)


__all__ = ["Background", "EarlyTiffs", "write_registered_tiff"]
