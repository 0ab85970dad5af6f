"""Errors the user can act on.

Anything raised as :class:`PlantregError` is shown to the user as its message
(CLI: one line on stderr and a non-zero exit; GUI: a dialog), never as a traceback.
Messages name the file and say what is wrong with it.
"""

from __future__ import annotations

from pathlib import Path


class PlantregError(Exception):
    """A user-facing error (bad input, impossible request)."""


class InputError(PlantregError):
    """A file or value given by the user is missing or malformed.

    ``path`` (optional) is the offending file; it is prefixed to the message.
    """

    def __init__(self, message: str, path: str | Path | None = None):
        self.path = Path(path) if path is not None else None
        message = one_line(message)  # the promise is one line, whatever a library said
        self.detail = message
        super().__init__(f"{show_path(self.path)}: {message}" if self.path is not None else message)


class Cancelled(PlantregError):
    """The user cancelled a long operation."""

    def __init__(self, message: str = "cancelled by the user"):
        super().__init__(message)


def show_path(path: str | Path) -> str:
    """A path as a message shows it: control characters (a newline or a tab in a file name) as
    escapes (``re\\nc``), so that the message stays one line and names the file unambiguously."""
    import re

    return re.sub(r"[\x00-\x1f\x7f]", lambda m: repr(m.group())[1:-1], str(path))


#: The error handler of the command line's standard streams (:func:`printable_streams`).
STREAM_ERRORS = "plantreg.names"


def _names_as_bytes_or_escapes(e: UnicodeError):
    """A file name that is not UTF-8 (Python holds its bytes as surrogates) is written as its own
    bytes; any other character the stream's encoding lacks (``ä`` with ``PYTHONIOENCODING=ascii``
    or an ASCII terminal) as a backslash escape, never a ``UnicodeEncodeError`` after the outputs
    are written."""
    if not isinstance(e, UnicodeEncodeError):
        raise e
    text = e.object[e.start:e.end]
    if all(0xDC80 <= ord(c) <= 0xDCFF for c in text):
        return bytes(ord(c) - 0xDC00 for c in text), e.end
    return text.encode("ascii", "backslashreplace").decode("ascii"), e.end


def printable_streams() -> None:
    """Standard output and error of a command-line process: every character printable whatever
    their encoding (see :func:`_names_as_bytes_or_escapes`)."""
    import codecs
    import sys

    try:
        codecs.lookup_error(STREAM_ERRORS)
    except LookupError:
        codecs.register_error(STREAM_ERRORS, _names_as_bytes_or_escapes)
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.reconfigure(errors=STREAM_ERRORS)
        except (AttributeError, ValueError):  # closed, or not a text stream of ours (captured in a test)
            pass


def said_once(path: str | Path | None, detail: str, within: str | Path) -> str:
    """An error about ``path`` in a line that names the folder ``within`` already (a failed batch
    row names its recording): a file inside it is named relative to it (``thermal.tif: ...``),
    the folder itself not again (it was "failed X: X: ..."), any other path in full."""
    import os

    if not path:
        return detail
    a, base = os.path.abspath(str(path)), os.path.abspath(str(within))
    if a == base:
        return detail
    if a.startswith(base.rstrip(os.sep) + os.sep):
        rel = os.path.relpath(a, base)
        return detail if detail.startswith(f"{rel} ") else f"{show_path(rel)}: {detail}"
    return f"{show_path(path)}: {detail}"


def one_line(text: str) -> str:
    """A library's message as one line: OpenCV's ``OpenCV(4.x) /path/file.cpp:123: error: (-215:...)
    ... in function 'f'`` loses its source location, and line breaks become ``; ``."""
    import re

    text = re.sub(r"OpenCV\([^)]*\)\s*\S+:\d+:\s*error:\s*", "", str(text))
    parts = [p.strip() for p in str(text).splitlines() if p.strip()]
    return "; ".join(parts)


def quiet_library_notes() -> None:
    """Silence the libraries' notes on stderr in a command-line process: numpy's floating-point
    ones (``RuntimeWarning: overflow encountered in matmul``, two lines with a source line) and
    tifffile's log lines about a malformed file (``<tifffile.TiffPages> invalid offset ...``). They
    are not messages for the user (the promise is one line): hostile values are refused by
    validation, naming the file and key, a bad file by its reader, naming the file and the
    reason, and a doubtful result is told by plantreg's own ``warning:`` lines."""
    import logging
    import warnings

    warnings.filterwarnings("ignore", message=r".*(overflow|invalid value|divide by zero|underflow) encountered",
                            category=RuntimeWarning)
    logging.getLogger("tifffile").setLevel(logging.ERROR + 1)  # its errors are raised to us as well
