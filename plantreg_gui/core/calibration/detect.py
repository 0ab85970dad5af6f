"""Board corners for a whole capture session: :func:`detect_session` / :func:`detect_views`
detect every (pose, camera) image in a pool of worker processes and keep the results in the
session's ``detections.json`` (:class:`DetectionCache`), so that a re-run, a recalibration after
excluding views and the wizard's resume do not detect again.

One image's detection is :func:`~.variants.detect_image`; the parts it is made of:
:mod:`.detection` (options, results and their JSON form), :mod:`.imageprep` (any image -> 8-bit
grey at a working scale), :mod:`.corners` (finding, checking, refining and ordering chessboard
corners: the corner order rule), :mod:`.variants` (what is tried on one image). Their public
names are importable from here too.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Iterator

import hashlib
import json
import stat

import cv2
import numpy as np

from ..errors import InputError, PlantregError
from ..io.imageio import atomic_write_text, has_write_bits, read_image
from ..progress import Reporter, ensure_reporter
from .corners import (MAX_IRREGULARITY, canonical_order, canonical_permutation,  # noqa: F401  (re-exported)
                      grid_irregularity, refine_corners)
from .detection import (DETECT_VERSION, DETECTORS, FAILED, FOUND, MISSING, VARIANT_TEXT, VARIANTS,  # noqa: F401
                        Detection, DetectOptions, check_image_sizes, detection_from_dict, detection_summary,
                        detection_to_dict)
from .imageprep import _palettes, flatten, to_gray, to_scalar, work_scale  # noqa: F401  (re-exported)
from .variants import detect_image, suggest_board_size  # noqa: F401  (re-exported)


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
        elif session.pose(key[0]).images.get(key[1]) is None:  # no image: nothing for a worker to do
            done += 1
            progress(done / n, f"{key[0]}/{key[1]}: missing")
            yield detect_view(session, session.pose(key[0]), key[1], opts.get(key)), None
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

                signals.stop_pool(pool, grace_s=2.0)
        ok = True
    finally:
        if cache is not None:
            cache.save()
    if ok:
        progress(1.0, "detection done")


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
