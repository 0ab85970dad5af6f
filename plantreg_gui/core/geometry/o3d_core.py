"""Open3D's compiled core (tensors, ``t.geometry.RaycastingScene``) without its Python package.

Why: ``import open3d`` runs ``open3d/__init__.py``, which unconditionally imports
``open3d.visualization`` and with it ``draw_plotly`` -> Dash, Plotly, Flask and (via Dash)
IPython: a large share of a command-line run that only casts rays. The ray caster lives in the compiled
extension module (``open3d/pybind*.so``, in Open3D < 0.19 ``open3d/cpu/pybind*.so``), which
needs nothing from the Python package. :func:`open3d_core` loads that extension by itself,
under the name the package gives it, so that a later ``import open3d`` (the GUI, a user's
script) finds it in ``sys.modules`` and reuses it instead of loading it twice.

If the extension cannot be found this way (an unusual build, a CUDA wheel), it falls back to
``import open3d`` -- slower start-up, same behaviour.
"""

from __future__ import annotations

import importlib.machinery
import importlib.util
import os
import sys
import threading
from pathlib import Path
from types import ModuleType

_LOCK = threading.Lock()
#: Module names of the compiled core, newest layout first (relative to the open3d package).
_CANDIDATES = ("pybind", "cpu.pybind")


def open3d_core() -> ModuleType:
    """The ``open3d.pybind`` extension module (has ``core.Tensor``, ``t.geometry.RaycastingScene``)."""
    with _LOCK:
        for rel in _CANDIDATES:
            mod = sys.modules.get(f"open3d.{rel}")
            if mod is not None:
                return mod
        if "open3d" in sys.modules:  # the whole package is already loaded: use it
            return _package_core()
        mod = _load_extension()
        return mod if mod is not None else _package_core()


def _package_core() -> ModuleType:
    import open3d

    return open3d.pybind if hasattr(open3d, "pybind") else sys.modules["open3d.cpu.pybind"]


def _load_extension() -> ModuleType | None:
    spec = importlib.util.find_spec("open3d")
    if spec is None or not spec.submodule_search_locations:
        return None
    root = Path(list(spec.submodule_search_locations)[0])
    for rel in _CANDIDATES:
        folder = root.joinpath(*rel.split(".")[:-1])
        for suffix in importlib.machinery.EXTENSION_SUFFIXES:
            so = folder / f"pybind{suffix}"
            if not so.is_file():
                continue
            name = f"open3d.{rel}"
            # open3d/__init__ sets this before its TBB is loaded (thread-pool sharing with Intel OpenMP)
            os.environ.setdefault("TCM_ENABLE", "1")
            loader = importlib.machinery.ExtensionFileLoader(name, str(so))
            ext_spec = importlib.util.spec_from_file_location(name, so, loader=loader)
            if ext_spec is None:
                return None
            try:
                mod = importlib.util.module_from_spec(ext_spec)
                sys.modules[name] = mod
                loader.exec_module(mod)
            except Exception:  # an unusual build: the package knows how to load itself
                sys.modules.pop(name, None)
                return None
            return mod
    return None


def load_in_background() -> threading.Thread:
    """Start loading the compiled core in a thread and return it (join it before exiting).

    Why: loading it takes long with the GIL held; started before the recording is read, it
    overlaps with the image decoding (OpenCV and numpy release the GIL). A failure is left to the
    first real call of :func:`open3d_core`, which reports it where it matters.
    """
    def load() -> None:
        try:
            open3d_core()
        except Exception:  # noqa: BLE001 - reported by the caller's own open3d_core() call
            pass

    t = threading.Thread(target=load, name="open3d-load", daemon=True)
    t.start()
    return t
