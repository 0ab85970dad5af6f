"""One plantreg run per output at a time: :func:`output_lock`, the one lock every command that
writes takes on its outputs (``register``, ``batch``, ``calibrate``, ``fit-rig``, ``rig create``,
``recording create``, ``demo``, the desktop app's export, the calibration wizard's save), from
before its long work until its outputs are in place.

The lock of an output ``P`` is the hidden file ``.NAME.plantreg-lock`` beside it (``NAME`` is
``P``'s name after following symbolic links, so two spellings of one output share one lock; a
name too long for that is shortened to 48 characters and a hash of the whole),
held with ``fcntl.flock``. A second run that wants the same output finds the lock taken and is
refused with one line naming the output and the holder (process id, host, command); it has
written nothing by then. The kernel releases a lock when its process ends however it ends, so a
lock file left by a killed run is recognised as free and taken over (by the lock, not by its age
or a process id that may have been reused). The file is removed on every exit path of the
holder (an exception, a signal: :mod:`..signals` turns those into exceptions).

Within one process the lock is re-entrant (``register`` holds its output while the export it
calls takes it again). No Qt.
"""

from __future__ import annotations

import os
import socket
import sys
import threading
from contextlib import ExitStack, contextmanager
from pathlib import Path
from typing import Iterator

from ..errors import InputError
from .. import signals

#: Suffix of a lock file (``.NAME.plantreg-lock`` beside the output NAME).
LOCK_SUFFIX = ".plantreg-lock"

_held: dict[Path, int] = {}  # lock file -> depth, in this process
_held_guard = threading.Lock()


def lock_path(out: str | Path, into: bool = False) -> Path:
    """The lock file of the output ``out``: ``.NAME.plantreg-lock`` in its folder, links followed.
    ``into``: ``out`` is an existing folder written into, never replaced (``batch``); where its
    parent folder cannot be written (a read-only project folder holding a writable OUT) the lock
    is ``OUT/.plantreg-lock`` instead."""
    from .paths import resolve

    r = resolve(out, "output path")
    if into and r.is_dir() and not os.access(r.parent, os.W_OK):
        return r / LOCK_SUFFIX
    name = f".{r.name}{LOCK_SUFFIX}"
    if len(os.fsencode(name)) > 255:  # a name near the file system's limit: shortened, kept unique
        import hashlib

        name = f".{r.name[:48]}.{hashlib.sha1(os.fsencode(r.name)).hexdigest()[:12]}{LOCK_SUFFIX}"
    return r.parent / name


def _holder_text() -> str:
    words = " ".join(["plantreg", *sys.argv[1:3]]) if sys.argv and sys.argv[0] else "plantreg"
    return f"{os.getpid()} {socket.gethostname()} {words}\n"


def _describe(holder: str) -> str:
    parts = holder.split(None, 2)
    if len(parts) >= 2 and parts[0].isdigit():
        cmd = f", {parts[2].strip()}" if len(parts) == 3 and parts[2].strip() else ""
        return f"process {parts[0]} on {parts[1]}{cmd}"
    return "its process id unknown"


class _FileLock:
    """One lock file held with ``flock`` (see the module doc)."""

    def __init__(self, path: Path, out: Path, what: str):
        self.path, self.out, self.what = path, out, what
        self._fd: int | None = None
        self._made: list[Path] = []

    def acquire(self) -> None:
        import fcntl

        missing = []
        p = self.path.parent
        while not os.path.lexists(p) and p != p.parent:
            missing.append(p)
            p = p.parent
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
        except OSError as e:
            raise InputError(f"{self.what} cannot be written: {self.path.parent} cannot be made "
                             f"({e.strerror or e})", self.out) from None
        self._made = missing  # removed again at release when still empty
        for _ in range(50):
            try:
                fd = os.open(self.path, os.O_RDWR | os.O_CREAT | getattr(os, "O_CLOEXEC", 0), 0o644)
            except OSError as e:
                self._remove_made()
                raise InputError(f"{self.what} cannot be written: its lock file {self.path.name} cannot be made "
                                 f"there ({e.strerror or e})", self.out) from None
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                try:
                    holder = os.read(fd, 400).decode("utf-8", "replace")
                finally:
                    os.close(fd)
                raise InputError(f"another plantreg run ({_describe(holder)}) is writing this {self.what}; wait for "
                                 "it to end, or choose another output", self.out) from None
            except BaseException:
                os.close(fd)
                raise
            try:  # the previous holder may have removed the file between our open and our lock
                same = os.fstat(fd).st_ino == os.stat(self.path).st_ino
            except FileNotFoundError:
                same = False
            if not same:
                os.close(fd)
                continue
            os.ftruncate(fd, 0)
            os.write(fd, _holder_text().encode())
            self._fd = fd
            return
        raise InputError("could not take the output's lock (its file keeps being replaced)", self.out)  # pragma: no cover

    def release(self) -> None:
        if self._fd is None:
            return
        # not under signals.deferred(): a terminating signal is what often brings us here, and
        # deferred() refuses to start once the process is ending; later signals are ignored then
        try:
            self.path.unlink(missing_ok=True)  # while still holding it: nobody else has it now
        finally:
            os.close(self._fd)
            self._fd = None
        self._remove_made()

    def _remove_made(self) -> None:
        for d in self._made:  # folders made only to hold the lock, if nothing else went there
            try:
                d.rmdir()
            except OSError:
                break
        self._made = []


@contextmanager
def output_lock(*outputs: str | Path, what: str = "output", into: bool = False) -> Iterator[None]:
    """Hold the lock of every output in ``outputs`` (files or folders; ``into``: see
    :func:`lock_path`) for the block; raises :class:`InputError` naming the output when another
    run holds one (nothing is held then). Locks are taken in a fixed order (no two runs wait on
    each other: a taken lock refuses at once)."""
    paths: dict[Path, Path] = {}
    for out in outputs:
        paths.setdefault(lock_path(out, into), Path(out))
    with ExitStack() as stack:
        for lp in sorted(paths):
            stack.enter_context(_one(lp, paths[lp], what))
        yield


@contextmanager
def _one(lp: Path, out: Path, what: str) -> Iterator[None]:
    with _held_guard:
        depth = _held.get(lp, 0)
        if depth:
            _held[lp] = depth + 1
    if depth:  # this process holds it already (an export inside register)
        try:
            yield
        finally:
            with _held_guard:
                _held[lp] -= 1
        return
    lock = _FileLock(lp, out, what)
    try:
        with signals.deferred():  # a lock file is never taken without its release being due
            lock.acquire()
            with _held_guard:
                _held[lp] = 1
        yield
    finally:
        with _held_guard:
            _held.pop(lp, None)
        lock.release()


__all__ = ["LOCK_SUFFIX", "lock_path", "output_lock"]
