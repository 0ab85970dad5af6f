"""A recording folder: one depth map and one image per camera.

``recording.json`` = ``{"depth": "depth.png", "images": {"ir": "ir.npy", "thermal": "thermal.tif"}}``,
paths relative to the folder. Images keep their values (see :mod:`.imageio`).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .errors import InputError
from .imageio import atomic_write_text, read_image, read_json
from .rig import Rig

MANIFEST = "recording.json"


@dataclass
class Recording:
    """``depth`` (H, W) raw depth units (multiply by ``rig.depth_scale`` for metres), 0 or NaN = no depth.
    ``images[name]`` (H, W) or (H, W, C) raw values. ``paths`` records where each came from."""

    folder: Path | None
    depth: np.ndarray | None
    images: dict[str, np.ndarray]
    paths: dict[str, Path] = field(default_factory=dict)
    extra: dict[str, Any] = field(default_factory=dict)

    def depth_m(self, scale: float) -> np.ndarray:
        """Depth in metres, float32 (H, W); NaN where there is no measurement."""
        if self.depth is None:
            raise InputError("the recording has no depth map", self.folder)
        from .depth import to_metres

        return to_metres(self.depth, scale)

    @classmethod
    def load(cls, folder: str | Path, rig: Rig | None = None) -> "Recording":
        """Read a recording folder; with ``rig``, check it against the rig (names and sizes)."""
        folder = Path(folder)
        if folder.is_file() and folder.name == MANIFEST:  # the manifest itself was given
            folder = folder.parent
        manifest = folder / MANIFEST
        if not folder.is_dir():
            raise InputError("recording folder not found", folder)
        if not manifest.is_file():
            raise InputError(f"not a recording folder (no {MANIFEST})", folder)
        m = read_json(manifest)
        if not isinstance(m, dict) or not isinstance(m.get("images", {}), dict):
            raise InputError("expected {\"depth\": FILE, \"images\": {CAMERA: FILE}}", manifest)
        paths: dict[str, Path] = {}
        images: dict[str, np.ndarray] = {}
        for name, rel in m.get("images", {}).items():
            p = folder / str(rel)
            if p.is_dir():
                raise InputError(f"image of camera '{name}' listed in {MANIFEST} is a folder, not a file", p)
            if not p.is_file():
                raise InputError(f"image of camera '{name}' listed in {MANIFEST} is missing", p)
            images[str(name)] = read_image(p)
            paths[str(name)] = p
        depth = None
        if m.get("depth"):
            p = folder / str(m["depth"])
            if p.is_dir():
                raise InputError(f"depth map listed in {MANIFEST} is a folder, not a file", p)
            if not p.is_file():
                raise InputError(f"depth map listed in {MANIFEST} is missing", p)
            depth = read_image(p)
            paths["depth"] = p
            if depth.ndim != 2:
                raise InputError(f"depth map must be single-channel, got shape {depth.shape}", p)
            if depth.dtype.kind not in "uif":
                raise InputError(f"depth map must hold real numbers, got dtype {depth.dtype}", p)
        extra = {k: v for k, v in m.items() if k not in ("depth", "images")}
        rec = cls(folder, depth, images, paths, extra)
        if rig is not None:
            rec.check(rig)
        return rec

    def check(self, rig: Rig, need_depth: bool = True) -> None:
        """Raise :class:`InputError` (naming the file) where the recording does not fit the rig."""
        for name, img in self.images.items():
            if name not in rig.names:
                raise InputError(
                    f"camera '{name}' of the recording is not in the rig ({', '.join(rig.names)})",
                    self.paths.get(name, self.folder),
                )
            cam = rig.camera(name)
            if img.shape[:2] != cam.shape:
                raise InputError(
                    f"image is {img.shape[1]}x{img.shape[0]} but camera '{name}' is "
                    f"{cam.width}x{cam.height} (width x height)",
                    self.paths.get(name, self.folder),
                )
        if need_depth:
            dcam = rig.depth()
            if self.depth is None:
                raise InputError("the recording has no depth map (\"depth\" in recording.json)", self.folder)
            p = self.paths.get("depth", self.folder)
            if self.depth.shape != dcam.shape:
                raise InputError(
                    f"depth map is {self.depth.shape[1]}x{self.depth.shape[0]} but depth camera "
                    f"'{dcam.name}' is {dcam.width}x{dcam.height}",
                    p,
                )
            with np.errstate(invalid="ignore"):
                if not np.any(np.asarray(self.depth, dtype=np.float64) > 0):
                    raise InputError("depth map is empty (no pixel has a depth > 0)", p)

    def save(self, folder: str | Path, names: dict[str, str] | None = None) -> None:
        """Write the images (``.npy`` unless ``names`` gives file names) and the manifest."""
        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        names = dict(names or {})
        m: dict[str, Any] = {"images": {}}
        for cam, img in self.images.items():
            fn = names.get(cam, f"{cam}.npy")
            _write_any(folder / fn, img)
            m["images"][cam] = fn
        if self.depth is not None:
            fn = names.get("depth", "depth.png")
            _write_any(folder / fn, self.depth)
            m["depth"] = fn
        m.update(self.extra)
        atomic_write_text(folder / MANIFEST, json.dumps(m, indent=2) + "\n")


def _write_any(path: Path, img: np.ndarray) -> None:
    from .imageio import atomic_path_suffixed, write_png, write_tiff

    s = path.suffix.lower()
    if s == ".npy":
        with atomic_path_suffixed(path) as tmp:
            np.save(tmp, img)
    elif s == ".png":
        write_png(path, img)
    elif s in (".tif", ".tiff"):
        write_tiff(path, img)
    elif s == ".hdr":
        import spectral.io.envi as envi

        envi.save_image(str(path), img, force=True, interleave="bsq")
    else:
        raise ValueError(f"cannot write {path.suffix}")
