"""Running a core routine in a child process, with progress and cancellation.

Some work holds Python's GIL for long stretches even on a worker thread (Open3D builds its ray
casting BVH and converts meshes inside one call; pure-Python loops), which freezes a GUI thread
waiting for the GIL. :func:`call_in_process` runs such a routine in a fresh ``spawn`` process
instead: its progress calls come back through a queue to the caller's
:class:`~plantreg_gui.core.progress.Reporter`, a cancel terminates the process (MNELAB's
``run_ica`` pattern). The routine, its arguments and its result must be picklable, so use it
for work whose result is small or on disk (e.g. writing the demo).
"""

from __future__ import annotations

import multiprocessing as mp
import queue
import time
import traceback
from typing import Any, Callable

from ..errors import Cancelled, PlantregError
from ..progress import Reporter, ensure_reporter


def _child(fn: Callable[..., Any], args: tuple, kwargs: dict, q: Any) -> None:
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
    ctx = mp.get_context("spawn")  # never fork a process that runs Qt threads
    q = ctx.Queue()
    p = ctx.Process(target=_child, args=(fn, args, kwargs, q), daemon=True)
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
    except Cancelled:
        p.terminate()
        raise
    finally:
        p.join(5.0)
        if p.is_alive():
            p.kill()
        q.close()


__all__ = ["call_in_process"]
