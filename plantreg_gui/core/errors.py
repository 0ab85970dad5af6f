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
        super().__init__(f"{self.path}: {message}" if self.path is not None else message)


class Cancelled(PlantregError):
    """The user cancelled a long operation."""

    def __init__(self, message: str = "cancelled by the user"):
        super().__init__(message)


def one_line(text: str) -> str:
    """A library's message as one line: OpenCV's ``OpenCV(4.x) /path/file.cpp:123: error: (-215:...)
    ... in function 'f'`` loses its source location, and line breaks become ``; ``."""
    import re

    text = re.sub(r"OpenCV\([^)]*\)\s*\S+:\d+:\s*error:\s*", "", str(text))
    parts = [p.strip() for p in str(text).splitlines() if p.strip()]
    return "; ".join(parts)
