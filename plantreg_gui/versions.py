"""Versions of plantreg and the libraries it runs on, for provenance (``summary.json``) and
Help ▸ About. Qt-free; imports nothing heavy: a library not yet imported is looked up by its
installed metadata's folder name."""

from __future__ import annotations

import platform
import sys
from pathlib import Path

from . import __version__

#: (label, import name, distribution names to look up when it is not imported yet)
LIBRARIES: tuple[tuple[str, str, tuple[str, ...]], ...] = (
    ("NumPy", "numpy", ("numpy",)),
    ("OpenCV", "cv2", ("opencv_python_headless", "opencv_python", "opencv_contrib_python_headless",
                       "opencv_contrib_python")),
    ("Open3D", "open3d", ("open3d", "open3d_cpu")),
    ("VTK", "vtkmodules", ("vtk",)),
    ("PySide6", "PySide6", ("PySide6_Essentials", "PySide6")),
)


def dist_version(module: str, dist: str | None = None) -> str | None:
    """The installed version of distribution ``dist`` (default: named like ``module``) whose
    import package ``module`` is, None if not installed; from the name of its
    ``<dist>-<version>.dist-info`` folder beside the module, without importing it. Why:
    ``importlib.metadata`` imports the ``email`` package and parses METADATA files: a share of a
    paper-sized ``plantreg register`` (its summary is written on the critical path)."""
    import importlib.util

    dist = dist or module
    try:
        spec = importlib.util.find_spec(module)
    except (ImportError, ValueError):
        spec = None
    if spec is None or not spec.origin:
        return None
    origin = Path(spec.origin)
    site = origin.parent.parent if origin.name == "__init__.py" else origin.parent
    prefix = dist.replace("-", "_").lower() + "-"
    try:
        found = [d.name for d in site.iterdir() if d.name.lower().startswith(prefix) and d.name.endswith(".dist-info")]
    except OSError:
        found = []
    if len(found) == 1:
        return found[0][len(prefix):-len(".dist-info")]
    try:  # several or none beside it (an unusual layout, a frozen bundle): ask the metadata
        from importlib.metadata import version

        return version(dist)
    except Exception:  # not installed / no metadata: say so, do not fail
        return None


def library_version(module: str, dists: tuple[str, ...] = ()) -> str | None:
    """The version of the installed distribution of ``module`` (the first of ``dists`` found: what
    pip shows, e.g. OpenCV's 5.0.0.93 where ``cv2.__version__`` says 5.0.0), else
    ``module.__version__`` if it is already imported, else None. Never imports ``module``."""
    for d in dists or (module,):
        v = dist_version(module, d)
        if v:
            return v
    mod = sys.modules.get(module)
    v = getattr(mod, "__version__", None) if mod is not None else None
    return v if isinstance(v, str) else None


def versions() -> list[tuple[str, str]]:
    """[(label, version)] of plantreg, Python and :data:`LIBRARIES` ("not installed" for a
    missing one)."""
    out = [("plantreg", __version__), ("Python", f"{platform.python_version()} ({sys.executable})")]
    for label, module, dists in LIBRARIES:
        out.append((label, library_version(module, dists) or "not installed"))
    return out
