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

A folder replaced as a whole (``register``'s and ``demo``'s OUT, the desktop app's export) and the
outputs inside it are one output: a run that writes ``OUT/rig.json`` is refused while another run
replaces ``OUT`` (it would be removed with the old ``OUT``), and a run that is to replace ``OUT``
is refused while another run writes inside it. Each run takes its own lock first and then looks
at the other's (ancestors' locks, or the locks inside the folder), so of two runs starting at the
same moment at least one sees the other.

Within one process the lock is re-entrant on the thread that holds it (``register`` holds its
output while the export it calls takes it again); another thread of the same process that wants
it (two exports of the desktop app into one folder) is refused like another run. No Qt.

:func:`claim_output` is how a command takes an output: the shared output-path check
(:func:`~.paths.check_output_location`) and the lock, in one call.
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

_held: dict[Path, tuple[int, int]] = {}  # lock file -> (holding thread, depth), in this process
_held_guard = threading.Lock()

#: What a lock's holder does with its output (the lock file's second line): ``replace`` a folder
#: as a whole (nobody may write inside it meanwhile), write ``into`` a folder (batch), or a ``file``.
REPLACE, INTO, FILE = "replace", "into", "file"


def lock_path(out: str | Path, into: bool = False) -> Path:
    """The lock file of the output ``out``: ``.NAME.plantreg-lock`` in its folder, links followed.
    ``into``: ``out`` is an existing folder written into, never replaced (``batch``); where its
    parent folder cannot be written (a read-only project folder holding a writable OUT) the lock
    is ``OUT/.plantreg-lock`` instead."""
    from .paths import resolve

    r = resolve(out, "output path")
    if into and r.is_dir() and not os.access(r.parent, os.W_OK):
        return r / LOCK_SUFFIX
    return _lock_file(r)


def _lock_file(r: Path) -> Path:
    """The lock file of the resolved path ``r``."""
    name = f".{r.name}{LOCK_SUFFIX}"
    if len(os.fsencode(name)) > 255:  # a name near the file system's limit: shortened, kept unique
        import hashlib

        name = f".{r.name[:48]}.{hashlib.sha1(os.fsencode(r.name)).hexdigest()[:12]}{LOCK_SUFFIX}"
    return r.parent / name


def _holder_text(mode: str = FILE) -> str:
    words = " ".join(["plantreg", *sys.argv[1:3]]) if sys.argv and sys.argv[0] else "plantreg"
    words = " ".join(words.split())  # one line, whatever the arguments hold
    return f"{os.getpid()} {socket.gethostname()} {words}\n{mode}\n"


def _describe(holder: str) -> str:
    parts = holder.split("\n", 1)[0].split(None, 2)
    if len(parts) >= 2 and parts[0].isdigit():
        cmd = f", {parts[2].strip()}" if len(parts) == 3 and parts[2].strip() else ""
        return f"process {parts[0]} on {parts[1]}{cmd}"
    return "its process id unknown"


class _FileLock:
    """One lock file held with ``flock`` (see the module doc)."""

    def __init__(self, path: Path, out: Path, what: str, mode: str = FILE):
        self.path, self.out, self.what, self.mode = path, out, what, mode
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
            try:  # who holds it, for the other run's message: on a full disk the lock is held without it
                os.ftruncate(fd, 0)
                os.write(fd, _holder_text(self.mode).encode())
            except OSError:
                pass
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


def _held_by_other(lock_file: Path) -> str | None:
    """The holder's text when another run (or another thread of this process) holds the lock
    file ``lock_file``; None when it is free or missing. Only looks: a shared lock taken and
    dropped at once, nothing created."""
    import fcntl

    with _held_guard:
        owner, depth = _held.get(lock_file, (None, 0))
    if depth:
        return None if owner == threading.get_ident() else f"{os.getpid()} {socket.gethostname()} plantreg\n"
    try:
        fd = os.open(lock_file, os.O_RDONLY | getattr(os, "O_CLOEXEC", 0) | getattr(os, "O_NOFOLLOW", 0))
    except OSError:
        return None
    try:
        holder = os.read(fd, 400).decode("utf-8", "replace")
        try:
            fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
        except BlockingIOError:
            return holder
        except OSError:
            return None
        fcntl.flock(fd, fcntl.LOCK_UN)
        return None
    finally:
        os.close(fd)


def _mode(holder: str) -> str:
    lines = holder.split("\n")
    return lines[1].strip() if len(lines) > 1 and lines[1].strip() else REPLACE  # not yet written: assume the most


def _check_neighbours(out: Path, what: str, mode: str) -> None:
    """Refuse ``out`` when a folder above it is being replaced as a whole by another run, or,
    for a folder to be replaced (``mode`` REPLACE), when another run writes inside it."""
    from .paths import resolve

    r = resolve(out, "output path")
    for a in r.parents:
        if a == a.parent:
            break
        holder = _held_by_other(_lock_file(a))
        if holder is not None and _mode(holder) == REPLACE:
            raise InputError(f"this {what} is inside {a}, which another plantreg run ({_describe(holder)}) is "
                             "replacing as a whole; wait for it to end, or choose another output", out)
    if mode == REPLACE and r.is_dir() and not r.is_symlink():
        for dp, dn, fn in os.walk(r):
            for f in fn:
                if f.endswith(LOCK_SUFFIX):
                    holder = _held_by_other(Path(dp) / f)
                    if holder is not None:
                        inner = Path(dp) / (f[1:-len(LOCK_SUFFIX)] if f != LOCK_SUFFIX else "")
                        raise InputError(f"another plantreg run ({_describe(holder)}) is writing {inner} inside this "
                                         f"{what}, which would be replaced as a whole; wait for it to end, or choose "
                                         "another output", out)


@contextmanager
def output_lock(*outputs: str | Path, what: str = "output", into: bool = False,
                whole: bool = False) -> Iterator[None]:
    """Hold the lock of every output in ``outputs`` (files or folders; ``into``: see
    :func:`lock_path`) for the block; raises :class:`InputError` naming the output when another
    run holds one (nothing is held then). Locks are taken in a fixed order (no two runs wait on
    each other: a taken lock refuses at once). ``whole``: the outputs are folders replaced as a
    whole (nobody may write inside them meanwhile; see the module doc)."""
    mode = INTO if into else (REPLACE if whole else FILE)
    paths: dict[Path, Path] = {}
    for out in outputs:
        paths.setdefault(lock_path(out, into), Path(out))
    with ExitStack() as stack:
        for lp in sorted(paths):
            stack.enter_context(_one(lp, paths[lp], what, mode))
        yield


@contextmanager
def _one(lp: Path, out: Path, what: str, mode: str = FILE) -> Iterator[None]:
    me = threading.get_ident()
    with _held_guard:
        owner, depth = _held.get(lp, (None, 0))
        if depth and owner == me:
            _held[lp] = (me, depth + 1)
    if depth and owner == me:  # this thread holds it already (an export inside register)
        try:
            yield
        finally:
            with _held_guard:
                _held[lp] = (me, _held[lp][1] - 1)
        return
    if depth:  # another thread of this process: refused like another run (two exports into one folder)
        raise InputError(f"another task of this program is writing this {what}; wait for it to end, or choose "
                         "another output", out)
    lock = _FileLock(lp, out, what, mode)
    try:
        with signals.deferred():  # a lock file is never taken without its release being due
            with _held_guard:
                if _held.get(lp, (None, 0))[1]:  # another thread took it meanwhile
                    raise InputError(f"another task of this program is writing this {what}; wait for it to end, "
                                     "or choose another output", out)
                _held[lp] = (me, 1)
            lock.acquire()
        _check_neighbours(out, what, mode)
        yield
    finally:
        with _held_guard:
            if _held.get(lp, (None, 0))[0] == me:
                _held.pop(lp, None)
        lock.release()


@contextmanager
def claim_output(out: str | Path, what: str = "output", *, folder: bool = False, overwrite: bool = False,
                 inputs=(), into: bool = False, lock_what: str | None = None,
                 replace_flag: str | None = "--overwrite") -> Iterator[Path]:
    """How a command takes an output, one mechanism for all: the shared output-path check
    (:func:`~.paths.check_output_location`: not an input, not a special file, writable, free or
    ``overwrite``), then the output's lock (a folder that is not written ``into`` is locked as
    replaced whole), held for the block. Yields the checked path. ``what`` names the output in
    messages (``lock_what`` in the lock's, when it differs); ``replace_flag`` as there."""
    from .paths import check_output_location

    out = check_output_location(out, what, folder=folder, overwrite=overwrite, inputs=inputs, into=into,
                                replace_flag=replace_flag)
    with output_lock(out, what=lock_what or what, into=into, whole=folder and not into):
        yield out


__all__ = ["LOCK_SUFFIX", "lock_path", "output_lock", "claim_output"]
