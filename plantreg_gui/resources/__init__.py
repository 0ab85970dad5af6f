"""Files the application ships inside the package (so a wheel or a frozen bundle has them too),
read through :mod:`importlib.resources`. Qt-free.

- ``plantreg.svg``: the application icon (window icon, desktop menu).
- ``plantreg-gui.desktop``: the freedesktop launcher template that ``plantreg-gui
  --install-desktop`` completes with the installed executable (``plantreg_gui/desktop.py``).
"""

from __future__ import annotations

import atexit
import contextlib
import functools
from importlib import resources
from pathlib import Path

ICON = "plantreg.svg"
DESKTOP_ENTRY = "plantreg-gui.desktop"
#: every file above, for the wheel and bundle checks
FILES = (ICON, DESKTOP_ENTRY)


def read_bytes(name: str) -> bytes:
    """The contents of the packaged resource ``name`` (one of :data:`FILES`)."""
    return resources.files(__name__).joinpath(name).read_bytes()


@functools.lru_cache(maxsize=None)
def path(name: str) -> Path:
    """A file-system path to the packaged resource ``name`` that stays valid for the process
    (Qt loads an SVG icon lazily, by file name). An ordinary install returns the file itself; a
    package read from a zip is extracted once to a temporary file, removed at exit."""
    stack = contextlib.ExitStack()
    atexit.register(stack.close)
    return Path(stack.enter_context(resources.as_file(resources.files(__name__).joinpath(name))))
