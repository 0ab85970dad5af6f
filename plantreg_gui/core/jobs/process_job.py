"""Run a long pure-Python routine in a child process, with the caller's progress and cancel.

Why: a routine that loops in Python (the joint bundle adjustment builds its Jacobian view by
view; the error tables mesh every depth map) holds the GIL on a worker *thread* most of the
time, and the GUI thread then waits for the GIL at every Qt call it makes -- the wizard froze
for seconds while calibrating. In a child process the GUI thread keeps the GIL to itself.

:func:`run_in_process` ``(fn, *args, progress=Reporter)`` calls ``fn(*args, progress=child
Reporter)`` in a single long-lived worker process (``spawn``: no forked Qt state) and blocks the
calling thread -- a GUI worker thread, never the GUI thread -- until it returns. Progress calls
in the child are forwarded to ``progress``; cancelling ``progress`` sets an event that the
child's Reporter checks at its next call, so the routine raises ``Cancelled`` as it would on a
thread. A child that does not react within :data:`CANCEL_GRACE_S` (a long native call) is
killed and a new one started on the next call. ``fn`` and its arguments must pickle (module-level
functions of the core, dataclasses, numpy arrays); errors raised in the child are re-raised here.

No Qt here: the child imports only ``fn``'s module.
"""

from __future__ import annotations

import concurrent.futures as cf
import itertools
import multiprocessing as mp
import queue
import threading
from typing import Any, Callable

from ..errors import Cancelled, PlantregError
from ..progress import CancelToken, Reporter, ensure_reporter

CANCEL_GRACE_S = 3.0

_lock = threading.Lock()  # one job at a time in the one child; others wait (cancellably)
_state_lock = threading.Lock()  # creating / killing the pool (held briefly: the GUI thread takes it)
_state: dict[str, Any] = {}  # "pool", "queue", "cancel"
_ids = itertools.count(1)
_exit_hook: list[bool] = []  # [True] once _kill_pool is registered with atexit

# --- in the child
_child: dict[str, Any] = {}


def _child_init(q, ev) -> None:
    import os

    _child["queue"], _child["cancel"], _child["parent"] = q, ev, os.getppid()


class _ChildToken(CancelToken):
    """Cancelled when the parent sets the event, or when the parent process is gone (a killed
    GUI must not leave its calculation running)."""

    def __init__(self, event, parent: int) -> None:
        super().__init__()
        self._event = event  # a multiprocessing Event: set by the parent
        self._parent = parent

    @property
    def cancelled(self) -> bool:
        import os

        return self._event.is_set() or os.getppid() != self._parent

    def raise_if_cancelled(self) -> None:
        if self.cancelled:
            raise Cancelled()


def _child_run(job: int, fn: Callable[..., Any], args: tuple, kwargs: dict) -> Any:
    q = _child["queue"]
    rep = Reporter(lambda f, m: q.put((job, float(f), str(m))), _ChildToken(_child["cancel"], _child["parent"]))
    return fn(*args, progress=rep, **kwargs)


def _noop(progress: Reporter | None = None) -> None:
    return None


# --- in the parent
def _pool() -> tuple[cf.ProcessPoolExecutor, Any, Any]:
    with _state_lock:
        return _pool_locked()


def _pool_locked() -> tuple[cf.ProcessPoolExecutor, Any, Any]:
    if "pool" not in _state:
        if not _exit_hook:
            # the pool must not live into the interpreter's teardown: freed there, its manager
            # thread's weakref callback ran after multiprocessing was gone ("Exception ignored in
            # ... weakref_cb ... AttributeError: 'NoneType' object has no attribute 'util'")
            import atexit

            atexit.register(_kill_pool)
            _exit_hook.append(True)
        ctx = mp.get_context("spawn")
        q, ev = ctx.Queue(), ctx.Event()
        _state["pool"] = cf.ProcessPoolExecutor(max_workers=1, mp_context=ctx, initializer=_child_init,
                                                initargs=(q, ev))
        _state["queue"], _state["cancel"] = q, ev
    return _state["pool"], _state["queue"], _state["cancel"]


def _kill_pool() -> None:
    with _state_lock:
        pool = _state.pop("pool", None)
        _state.pop("queue", None)
        _state.pop("cancel", None)
    if pool is None:
        return
    for p in list(getattr(pool, "_processes", {}).values()):  # no public terminate()
        p.terminate()
    pool.shutdown(wait=False, cancel_futures=True)


def warm_up() -> None:
    """Start the child process now (it imports NumPy, OpenCV, SciPy: about a second) so that the
    first job does not wait for it. Returns at once (never waits for a running job)."""
    _pool()[0].submit(_noop)


def run_in_process(fn: Callable[..., Any], *args: Any, progress: Reporter | None = None, **kwargs: Any) -> Any:
    """``fn(*args, progress=Reporter, **kwargs)`` in the worker process (see the module docstring)."""
    progress = ensure_reporter(progress)
    while not _lock.acquire(timeout=0.1):
        progress.check()
    try:
        pool, q, ev = _pool()
        ev.clear()
        while True:  # progress left over from a killed job
            try:
                q.get_nowait()
            except queue.Empty:
                break
        job = next(_ids)
        fut = pool.submit(_child_run, job, fn, args, kwargs)
        cancelled_at = None
        while True:
            try:
                j, f, m = q.get(timeout=0.05)
                if j == job and cancelled_at is None:
                    progress(f, m)
            except queue.Empty:
                pass
            except Cancelled:
                pass  # handled below through the token
            if cancelled_at is None and progress.cancel.cancelled:
                ev.set()
                cancelled_at = _now()
            if fut.done():
                break
            if cancelled_at is not None and _now() - cancelled_at > CANCEL_GRACE_S:
                _kill_pool()
                raise Cancelled()
        try:
            result = fut.result()
        except cf.process.BrokenProcessPool:
            _kill_pool()
            if cancelled_at is not None:
                raise Cancelled() from None
            raise PlantregError("the calculation's worker process ended unexpectedly (out of memory?)") from None
        if cancelled_at is not None:
            raise Cancelled()
        return result
    finally:
        _lock.release()


def _now() -> float:
    import time

    return time.monotonic()
