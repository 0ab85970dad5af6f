"""Paths the user gives, checked in one place: every input file or folder a command reads and
every output it writes goes through here, so that an unusual path (a NUL byte, a symbolic link
loop, a FIFO, a device, a folder where a file is expected, a name too long for the file system)
is one :class:`~plantreg_gui.core.errors.InputError` naming the user's path -- never a
``ValueError: embedded null byte`` or ``RuntimeError: Symlink loop`` from deep inside.

* :func:`check_input_file`, :func:`check_input_folder`: what a command reads.
* :func:`check_output_location`: what a command writes, before any expensive work (the command
  line calls it first); :func:`check_destination` is its cheap part, which the atomic writers
  (:mod:`.imageio`) run again on every destination, so the GUI's saves get it too.
* :func:`temp_beside`: the hidden temporary name an output is built under; its errors name the
  user's path (a 250-character name, no inodes left), never ``.NAME.XXXX.part``.

The promise (docs/errors.md, "Paths, names and outputs"): an output is never one of the
command's inputs, never a folder holding one of them, never the current folder or one above
it, never a FIFO, device or socket, and ``--overwrite`` never changes that.
"""

from __future__ import annotations

import errno
import os
import stat
import tempfile
from pathlib import Path
from typing import Iterable

from .. import signals
from ..errors import InputError

#: Characters of a user's file name kept in a temporary name beside it (the rest of the name is
#: dropped there: ``.NAME.XXXXXXXX.part.SUFFIX`` must fit the file system's 255 bytes).
_TEMP_STEM = 48


def _kind(mode: int) -> str:
    """A file type as the user knows it."""
    if stat.S_ISDIR(mode):
        return "a folder"
    if stat.S_ISFIFO(mode):
        return "a FIFO (named pipe)"
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "a device"
    if stat.S_ISSOCK(mode):
        return "a socket"
    return "a regular file" if stat.S_ISREG(mode) else "a special file"


def _os_problem(e: OSError) -> str:
    """An OS error on a path as the words the user needs."""
    if e.errno == errno.ELOOP:
        return "is a symbolic link loop (a link that points back to itself)"
    if e.errno == errno.ENAMETOOLONG:
        return "is too long a name for the file system"
    if e.errno == errno.ENOTDIR:
        return "cannot be reached: a part of its path is a file, not a folder"
    if e.errno in (errno.EACCES, errno.EPERM):
        return "cannot be reached (permission denied on a folder of its path)"
    return f"cannot be read ({e.strerror or e})"


def check_path_text(path: str | Path, what: str = "path") -> Path:
    """``path`` as a Path; refused: empty (an unset shell variable would mean the current
    folder) or holding a NUL character (no file system allows one; Python raises
    ``ValueError: embedded null byte`` on it)."""
    if str(path) == "":
        raise InputError(f"{what} is empty (an unset shell variable?)")
    if "\x00" in str(path):
        raise InputError(f"{what} contains a NUL character, which no file name can hold",
                         str(path).replace("\x00", "\\0"))
    return Path(path)


def stat_or_none(path: str | Path, what: str = "file", follow: bool = True) -> os.stat_result | None:
    """``os.stat`` (``os.lstat`` unless ``follow``), None when nothing is there; every other
    problem (NUL, loop, a file in the path, permission) is an :class:`InputError` naming it."""
    path = check_path_text(path, what)
    try:
        return os.stat(path) if follow else os.lstat(path)
    except FileNotFoundError:
        return None
    except OSError as e:
        raise InputError(f"{what} {_os_problem(e)}", path) from None


def resolve(path: str | Path, what: str = "path") -> Path:
    """The absolute path with every symbolic link followed; a loop is refused naming ``path``
    (``Path.resolve`` raises ``RuntimeError`` for it)."""
    path = check_path_text(path, what)
    try:
        return path.resolve()
    except RuntimeError:
        raise InputError(f"{what} is a symbolic link loop (a link that points back to itself)", path) from None
    except OSError as e:
        raise InputError(f"{what} {_os_problem(e)}", path) from None


#: Every file and folder this command has read so far (resolved), when :func:`remember_reads` was
#: called (the command line: everything a command reads is one of its inputs). An output is never
#: one of them, even where a command's own list of its inputs misses one (``calibrate
#: --intrinsics cam=RIG.json --out RIG.json --overwrite`` replaced the file it had read). The
#: desktop app does not keep it: over a session it reads much that is not an input of an export.
_reads: set[Path] | None = None


def remember_reads(on: bool = True) -> None:
    """From now on note every input path checked here (see :data:`_reads`), starting afresh;
    ``on=False``: stop (the command has ended)."""
    global _reads
    _reads = set() if on else None


def _note_read(path: str | Path) -> None:
    if _reads is not None:
        r = _resolved_or_none(path)
        if r is not None:
            _reads.add(r)


def _resolved_or_none(path: str | Path) -> Path | None:
    try:
        return Path(path).resolve() if "\x00" not in str(path) else None
    except (RuntimeError, OSError, ValueError):
        return None


def check_input_file(path: str | Path, what: str = "file") -> Path:
    """Raise :class:`InputError` naming ``path`` unless it is an existing, readable regular file.

    A folder, FIFO, socket or device (``/dev/zero``) is refused as "not a regular file" (reading
    a FIFO would block, a device never ends); a permission problem, a link loop and a NUL
    character are named as such.
    """
    st = stat_or_none(path, what)
    path = Path(path)
    if st is None:
        if os.path.islink(path):
            raise InputError(f"{what} is a symbolic link to nothing (its target is missing)", path)
        raise InputError(f"{what} is missing (not found)", path)
    if not stat.S_ISREG(st.st_mode):
        raise InputError(f"{what} is {_kind(st.st_mode)}, not a regular file", path)
    try:
        with open(path, "rb"):
            pass
    except PermissionError:
        raise InputError(f"{what} is not readable (permission denied)", path) from None
    except OSError as e:
        raise InputError(f"{what} cannot be read ({e.strerror or e})", path) from None
    _note_read(path)
    return path


def check_input_folder(path: str | Path, what: str = "folder") -> Path:
    """Raise :class:`InputError` naming ``path`` unless it is an existing folder."""
    st = stat_or_none(path, what)
    path = Path(path)
    if st is None:
        raise InputError(f"{what} does not exist", path)
    if not stat.S_ISDIR(st.st_mode):
        raise InputError(f"{what} is {_kind(st.st_mode)}, not a folder", path)
    _note_read(path)
    return path


def _nearest_existing(p: Path) -> Path:
    p = p.absolute()
    while not os.path.lexists(p) and p != p.parent:
        p = p.parent
    return p


def check_destination(out: str | Path, what: str = "output", *, folder: bool = False) -> Path:
    """The cheap part of :func:`check_output_location`, run by every atomic writer: ``out`` is not
    empty, holds no NUL, is not a symbolic link loop, is not a FIFO, device or socket (renaming
    onto ``/dev/null`` would replace the device itself), not a file where a folder is wanted or
    vice versa, and its name fits the file system (``lstat`` says ENAMETOOLONG otherwise)."""
    out = check_path_text(out, f"{what} path")
    st = stat_or_none(out, f"{what} path", follow=False)
    if st is not None and stat.S_ISLNK(st.st_mode):
        resolve(out, f"{what} path")  # a loop is refused; a dangling link is replaced like a file
        target = stat_or_none(out, f"{what} path")
        st = target if target is not None else None
    if st is not None:
        if not (stat.S_ISREG(st.st_mode) or stat.S_ISDIR(st.st_mode)):
            raise InputError(f"{what} path is {_kind(st.st_mode)}; plantreg writes regular files and folders only", out)
        if folder and not stat.S_ISDIR(st.st_mode):
            raise InputError(f"{what} path exists and is not a folder", out)
        if not folder and stat.S_ISDIR(st.st_mode):
            raise InputError(f"{what} path is a folder, expected a file name", out)
    return out


def check_output_location(out: str | Path, what: str = "output", *, folder: bool = False,
                          overwrite: bool = False, inputs: Iterable[str | Path] = (), into: bool = False,
                          replace_flag: str | None = "--overwrite") -> Path:
    """Validate an output path before any expensive work; raises :class:`InputError` naming it.

    Refused, besides :func:`check_destination`: a path that is one of ``inputs`` or of the paths
    the command has read so far (:func:`remember_reads`; files or folders, compared after
    following links), or a folder holding one of them; the current
    folder or one above it (replacing it would pull the ground from under the shell); an
    existing output unless ``overwrite`` (a non-empty folder when ``folder``, any file
    otherwise); a mount point to be replaced; a location where no file can be created (probed by
    creating and removing a hidden temporary file there, which also catches read-only file
    systems and root-squashed mounts that permission bits do not show). ``into``: the command
    writes inside an existing folder ``out`` without replacing it (``plantreg batch``): an
    existing folder is accepted as it is. ``replace_flag``: how messages name the way to replace
    an output (the desktop app, which asks instead, passes None: no command-line flag in a dialog).
    """
    out = check_destination(out, what, folder=folder)
    out_r = resolve(out, f"{what} path")
    given = list(inputs)
    # what was read besides the given inputs: never the output; inside an output folder only when
    # that folder is replaced (not ``into``: batch writes beside a list file kept in OUT)
    for p, inside_counts in [*((p, True) for p in given), *((p, not into) for p in sorted(_reads or ()))]:
        p_r = _resolved_or_none(p)
        if p_r is not None and (p_r == out_r or (inside_counts and out_r in p_r.parents)):
            inside = "" if p_r == out_r else ", which is inside it"
            never = f"{replace_flag} never replaces an input" if replace_flag else "an input is never replaced"
            raise InputError(f"the {what} would replace an input of this command ({p}{inside}); choose a location "
                             f"outside the inputs ({never})", out)
    if folder and not into:
        try:
            cwd = _resolved_or_none(os.getcwd())
        except OSError:  # the current folder was removed: it cannot be the output
            cwd = None
        if cwd is not None and (out_r == cwd or out_r in cwd.parents):
            raise InputError(f"the {what} folder is the current folder or holds it; plantreg replaces its output "
                             "folder as a whole: name a new folder (e.g. out)", out)
    if os.path.lexists(out) and not (out.is_symlink() and not out.exists()) and not into:
        if folder and any(out.iterdir()) and not overwrite:
            how = f", or pass {replace_flag}" if replace_flag else ""
            raise InputError(f"{what} folder exists and is not empty (choose another{how})", out)
        if not folder and not overwrite:
            how = f", or pass {replace_flag} to replace it" if replace_flag else ""
            raise InputError(f"{what} file exists (choose another name{how})", out)
        if overwrite and folder and out.is_dir() and not out.is_symlink() and os.path.ismount(out):
            raise InputError(f"{what} folder is a mount point and cannot be replaced; choose a folder inside it", out)
    base = _nearest_existing(out if into and out.is_dir() else out.parent)
    if not base.is_dir():
        raise InputError(f"{what} cannot be made: {base} is a file, not a folder", out)
    try:
        with signals.deferred():  # the probe is never left behind by a signal
            fd, probe = tempfile.mkstemp(prefix=".plantreg-probe.", dir=base)
            os.close(fd)
            os.unlink(probe)
    except OSError as e:
        raise InputError(f"{what} cannot be written: {base} is not writable ({e.strerror or e})", out) from None
    return out


def temp_beside(final: str | Path, *, folder: bool = False, suffix: str = ".part") -> Path:
    """Create a hidden temporary file (or ``folder``) beside ``final``, named
    ``.STEM.XXXXXXXX<suffix><final's suffix>`` (files keep their suffix: writers choose the format
    by it) with the stem shortened so a 250-character name still fits. OS errors (no space, no
    inodes, no permission) name ``final``, never the temporary name."""
    final = Path(final)
    stem = (final.name if folder else final.stem)[:_TEMP_STEM]
    try:
        final.parent.mkdir(parents=True, exist_ok=True)
        if folder:
            return Path(tempfile.mkdtemp(prefix=f".{stem}.", suffix=suffix, dir=final.parent))
        ext = final.suffix if len(final.suffix) <= 16 else ""
        fd, tmp = tempfile.mkstemp(prefix=f".{stem}.", suffix=f"{suffix}{ext}", dir=final.parent)
        os.close(fd)
        return Path(tmp)
    except OSError as e:
        raise OSError(e.errno, e.strerror or str(e), str(final)) from None


__all__ = ["remember_reads", "check_path_text", "stat_or_none", "resolve", "check_input_file", "check_input_folder",
           "check_destination", "check_output_location", "temp_beside"]
