"""Child processes for long core work, with the caller's progress and cancel: the one place for them.

Why: a routine that loops in Python (the joint bundle adjustment builds its Jacobian view by
view; the error tables mesh every depth map) or holds the GIL inside one call (Open3D builds
its ray casting BVH) holds the GIL on a worker *thread* most of the time, and the GUI thread
then waits for the GIL at every Qt call it makes -- the wizard froze for seconds while
calibrating. In a child process the GUI thread keeps the GIL to itself. Two ways:

* :func:`run_in_process` ``(fn, *args, progress=Reporter)`` calls ``fn(*args, progress=child
  Reporter)`` in a single long-lived worker process (``spawn``: no forked Qt state) and blocks
  the calling thread -- a GUI worker thread, never the GUI thread -- until it returns. Progress
  calls in the child are forwarded to ``progress``; cancelling ``progress`` sets an event that
  the child's Reporter checks at its next call, so the routine raises ``Cancelled`` as it would
  on a thread. A child that does not react within :data:`CANCEL_GRACE_S` (a long native call)
  is ended and a new one started on the next call. For repeated jobs (the wizard's steps).
* :func:`call_in_process` runs one routine in a fresh ``spawn`` process; a cancel ends it at
  once (MNELAB's ``run_ica`` pattern). For one-off work whose result is small or on disk (e.g.
  writing the demo, a landmark refinement).

``fn``, its arguments and its result must pickle (module-level functions of the core,
dataclasses, numpy arrays); a :class:`PlantregError` raised in the child is re-raised here.
Every child runs :func:`~plantreg_gui.core.signals.child_init` (a signal to the process group
makes it remove its temporary outputs) and is ended with
:func:`~plantreg_gui.core.signals.stop_processes` (SIGTERM, a grace period, SIGKILL). No Qt here: the child imports only ``fn``'s module.
"""

from __future__ import annotations

import concurrent.futures as cf
import itertools
import queue
import threading
import time
import traceback
from typing import Any, Callable

from .. import signals
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

    signals.child_init()
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


#: the fraction of a job's last message: every progress message of the job came before it (one
#: queue, one feeder thread), and the result comes through the pool's own channel, which may
#: overtake them on a loaded machine
_END = -1.0
#: how long the parent waits for a finished job's last messages (a job whose process died sends none)
END_WAIT_S = 10.0


def _child_run(job: int, fn: Callable[..., Any], args: tuple, kwargs: dict) -> Any:
    q = _child["queue"]
    rep = Reporter(lambda f, m: q.put((job, float(f), str(m))), _ChildToken(_child["cancel"], _child["parent"]))
    try:
        return fn(*args, progress=rep, **kwargs)
    finally:
        q.put((job, _END, ""))


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
        ctx = signals.spawn_context()
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
    signals.stop_pool(pool, grace_s=2.0)


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
        cancelled_at = done_at = None
        ended = False
        while True:
            try:
                j, f, m = q.get(timeout=0.05)
                if j == job and f == _END:
                    ended = True
                elif j == job and cancelled_at is None:
                    progress(f, m)
            except queue.Empty:
                pass
            except Cancelled:
                pass  # handled below through the token
            if cancelled_at is None and progress.cancel.cancelled:
                ev.set()
                cancelled_at = _now()
            if fut.done():
                # the job's progress may still be on its way: wait for its last message (none
                # comes from a process that died)
                if ended or cancelled_at is not None or isinstance(fut.exception(), cf.process.BrokenProcessPool):
                    break
                done_at = done_at if done_at is not None else _now()
                if _now() - done_at > END_WAIT_S:
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
    return time.monotonic()


# ---------------------------------------------------------------------- one routine, a fresh process
def _one_child(fn: Callable[..., Any], args: tuple, kwargs: dict, q: Any) -> None:
    signals.child_init()
    last = [0.0]

    def report(f: float, m: str) -> None:
        now = time.monotonic()
        if now - last[0] > 0.05:  # at most 20 messages a second through the pipe
            last[0] = now
            q.put(("progress", f, m))

    try:
        out = fn(*args, progress=Reporter(report), **kwargs)
    except PlantregError as e:
        q.put(("plantreg", str(e), ""))
    except BaseException as e:  # noqa: BLE001 - every failure must reach the parent
        q.put(("error", f"{type(e).__name__}: {e}", traceback.format_exc()))
    else:
        q.put(("done", out, None))


def call_in_process(fn: Callable[..., Any], *args: Any, progress: Reporter | None = None, **kwargs: Any) -> Any:
    """``fn(*args, progress=Reporter, **kwargs)`` in a child process; returns its result.

    Raises :class:`~plantreg_gui.core.errors.Cancelled` (after terminating the child) when
    ``progress`` is cancelled, :class:`PlantregError` with the child's message when it raised
    one, ``RuntimeError`` for anything else (the child's traceback in the message)."""
    rep = ensure_reporter(progress)
    ctx = signals.spawn_context()  # never fork a process that runs Qt threads
    q = ctx.Queue()
    p = ctx.Process(target=_one_child, args=(fn, args, kwargs, q), daemon=True)
    p.start()
    try:
        while True:
            try:
                kind, a, b = q.get(timeout=0.05)
            except queue.Empty:
                rep.check()
                if not p.is_alive() and q.empty():
                    raise RuntimeError(f"the worker process ended without a result (exit code {p.exitcode})")
                continue
            if kind == "progress":
                rep(a, b)
            elif kind == "done":
                return a
            elif kind == "plantreg":
                raise PlantregError(a)
            else:
                raise RuntimeError(f"{a}\n{b}")
    except BaseException:  # cancelled, failed, or this process is ending: so is the child
        signals.stop_processes([p])
        raise
    finally:
        p.join(5.0)
        if p.is_alive():
            p.kill()
        q.close()


__all__ = ["run_in_process", "call_in_process", "warm_up", "CANCEL_GRACE_S"]
