"""Terminating signals: one mechanism for the command line, every thread and every child process.

A signal that ends a process (SIGTERM from ``kill``, ``timeout``, systemd or Slurm -- often sent
to the whole process group --, SIGHUP from a closed terminal, SIGINT, SIGQUIT, SIGUSR1/2, SIGALRM,
SIGXCPU from a CPU-time limit, SIGVTALRM) must leave no temporary output behind. So:

* :func:`install` (the CLI, on the main thread) turns each of them into an exception raised on
  the main thread -- :class:`Terminated`, or ``KeyboardInterrupt`` for SIGINT -- which unwinds
  like any error, through every ``atomic_*`` writer's cleanup. Later signals are ignored while
  it unwinds (SIGXCPU comes again every CPU second). A signal whose disposition was "ignore" when
  the program started (``nohup``) stays ignored.
* :func:`deferred` (any thread) holds such a signal while a few renames move a complete result
  into place: Python runs signal handlers on the main thread whichever thread the kernel chose,
  so a per-thread signal mask cannot do this (calibrate's renames were interrupted through a
  signal delivered to one of its other threads). The signal is acted on when the last deferred
  section on any thread ends; once the process is terminating no new section starts.
* :func:`child_init` (the initializer of every child process we spawn) installs the same
  handlers in the child, which then removes its own temporary outputs when the process group is
  signalled; an idle child just exits. :func:`stop_processes` is how a parent ends its children:
  SIGTERM (so they clean up), a grace period, then SIGKILL.

No Qt here. In a process that did not call :func:`install` (the GUI), :func:`deferred` only
counts, and signals keep their usual effect.
"""

from __future__ import annotations

import signal
import threading
from contextlib import contextmanager
from typing import Iterable, Iterator

#: Signals whose default action ends the process and that a user or a batch system sends to stop
#: a run (SIGINT raises KeyboardInterrupt, the others :class:`Terminated`).
TERMINATING = tuple(getattr(signal, name) for name in
                    ("SIGTERM", "SIGHUP", "SIGINT", "SIGQUIT", "SIGUSR1", "SIGUSR2", "SIGALRM", "SIGXCPU",
                     "SIGVTALRM")
                    if hasattr(signal, name))

#: Seconds a child process is given to clean up after SIGTERM before it is killed.
CHILD_GRACE_S = 5.0


class Terminated(SystemExit):
    """A terminating signal arrived: unwinds like Ctrl-C, so every temporary output is removed.

    A ``SystemExit`` (not an ``Exception``: no ``except Exception`` of a worker swallows it) whose
    code is ``128 + signum``, the shell's convention, so that a child process that ends with it
    exits quietly with that status."""

    def __init__(self, signum: int):
        super().__init__(signum)
        self.signum = int(signum)
        self.code = 128 + self.signum

    def __reduce__(self):  # picklable across a process pool
        return (Terminated, (self.signum,))


_lock = threading.Lock()
_depth = 0                       # deferred sections open, on all threads
_pending: int | None = None      # a signal held by a deferred section
_terminating: int | None = None  # the signal that is ending this process
_raised = False                  # its exception has been raised on the main thread


def _exception(signum: int) -> BaseException:
    return KeyboardInterrupt() if signum == signal.SIGINT else Terminated(signum)


def _handler(signum: int, frame) -> None:
    """Runs on the main thread (CPython's rule). Never takes ``_lock``: the main thread may hold it."""
    global _pending, _terminating, _raised
    if _raised:
        return  # already unwinding
    if _depth > 0:
        if _pending is None:
            _pending = signum
        return
    _terminating = _terminating or signum
    _raised = True
    raise _exception(_terminating)


def install() -> dict[int, object]:
    """Handle :data:`TERMINATING` (main thread only; elsewhere nothing happens). Returns the
    previous handlers, for :func:`uninstall`."""
    global _terminating, _pending, _raised
    if threading.current_thread() is not threading.main_thread():
        return {}
    _terminating = _pending = None
    _raised = False
    old: dict[int, object] = {}
    for sig in TERMINATING:
        try:
            prev = signal.getsignal(sig)
            if prev is signal.SIG_IGN:
                continue  # nohup and friends: the caller asked that this signal not stop us
            signal.signal(sig, _handler)
            old[sig] = prev
        except (OSError, ValueError):  # pragma: no cover - platform without the signal
            pass
    return old


def uninstall(old: dict[int, object]) -> None:
    """Put back the handlers :func:`install` returned; the process is no longer terminating."""
    global _terminating, _pending, _raised
    for sig, h in old.items():
        try:
            signal.signal(sig, h if h is not None else signal.SIG_DFL)
        except (OSError, ValueError):  # pragma: no cover
            pass
    _terminating = _pending = None
    _raised = False


def terminating() -> int | None:
    """The signal that is ending this process, or None."""
    return _terminating


def check() -> None:
    """Raise :class:`Terminated` (``KeyboardInterrupt`` for SIGINT) if the process is being ended:
    for loops on worker threads, which no signal handler interrupts."""
    if _terminating is not None:
        raise _exception(_terminating)


@contextmanager
def deferred() -> Iterator[None]:
    """Hold terminating signals (see the module docstring) while the block runs, on any thread."""
    global _depth, _pending, _terminating
    with _lock:
        if _terminating is not None:  # the process is ending: no result is moved into place any more
            raise _exception(_terminating)
        _depth += 1
    try:
        yield
    finally:
        with _lock:
            _depth -= 1
            sig = _pending if _depth == 0 else None
            if sig is not None:
                _pending = None
                _terminating = _terminating or sig  # from now on, no new section starts
        if sig is not None:
            if threading.current_thread() is threading.main_thread():
                _handler(sig, None)
            else:  # a real signal to the main thread: it also wakes it from a blocking wait
                signal.pthread_kill(threading.main_thread().ident, sig)


def child_init() -> None:
    """In every child process we spawn: the same handling as the parent's CLI. A signal while the
    child runs a job unwinds the job (its temporary outputs are removed, the parent gets the
    exception); while idle, the child exits with status 128 + signal and no traceback. The
    libraries' notes on stderr are silenced as in the CLI (:func:`~.errors.quiet_library_notes`)."""
    from .errors import quiet_library_notes

    quiet_library_notes()
    install()


def spawn_context():
    """``multiprocessing``'s ``spawn`` context for every child process we start (no forked Qt or
    thread state). First starts multiprocessing's resource-tracker process, if it is not running,
    with :data:`TERMINATING` blocked: it shares our process group, and dying from a SIGHUP or
    SIGQUIT meant to stop us, it was restarted and printed tracebacks (it blocks only SIGINT and
    SIGTERM by itself). Blocked here, not ignored, so that no signal to us is lost meanwhile."""
    import multiprocessing as mp
    from multiprocessing import resource_tracker

    old = signal.pthread_sigmask(signal.SIG_BLOCK, set(TERMINATING))
    try:
        resource_tracker.ensure_running()
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)
    return mp.get_context("spawn")


def stop_processes(procs: Iterable, grace_s: float = CHILD_GRACE_S) -> None:
    """End child processes (``multiprocessing.Process``): SIGTERM to all (they clean up, see
    :func:`child_init`), wait up to ``grace_s`` in all, then SIGKILL what is left."""
    import time

    procs = [p for p in procs if p is not None]
    for p in procs:
        try:
            if p.is_alive():
                p.terminate()
        except (OSError, ValueError, AssertionError):  # already reaped / not started
            pass
    end = time.monotonic() + grace_s
    for p in procs:
        try:
            p.join(max(0.0, end - time.monotonic()))
            if p.is_alive():  # still starting up (spawn) or stuck in native code
                p.kill()
                p.join(2.0)
        except (OSError, ValueError, AssertionError):
            pass


def stop_pool(pool, grace_s: float = CHILD_GRACE_S, timeout_s: float = 20.0) -> None:
    """Shut a ``concurrent.futures.ProcessPoolExecutor`` down without waiting for its jobs and end
    its workers (:func:`stop_processes`), also those its management thread starts while it winds
    down (a loaded machine starts a spawned worker late): stop, and look again until that thread
    has ended and no new worker appeared."""
    import time

    # shutdown() forgets both (the pool has no public list); the thread goes on adding workers to the same dict
    workers = getattr(pool, "_processes", None) or {}
    thread = getattr(pool, "_executor_manager_thread", None)
    pool.shutdown(wait=False, cancel_futures=True)
    seen: list = []
    end = time.monotonic() + timeout_s
    while True:
        new = [p for p in list(workers.values()) if p not in seen]
        stop_processes(new, grace_s=grace_s)
        seen += new
        if thread is not None and thread.is_alive() and time.monotonic() < end:
            thread.join(0.2)
            continue
        if not [p for p in list(workers.values()) if p not in seen] or time.monotonic() >= end:
            return


__all__ = ["TERMINATING", "Terminated", "install", "uninstall", "terminating", "check", "deferred", "child_init",
           "spawn_context", "stop_processes", "stop_pool"]
