"""A recording folder: one depth map and one image per camera.

``recording.json`` = ``{"depth": "depth.png", "images": {"ir": "ir.npy", "thermal": "thermal.tif"}}``,
paths relative to the folder. Images keep their values (see :mod:`.imageio`).
"""

from __future__ import annotations

import glob
import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

from ..errors import InputError
from ..io.imageio import atomic_write_text, image_decoder, read_json
from ..io.paths import check_input_file, check_input_folder
from ..camera.rig import Rig

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
    #: metres per depth unit of this recording (``"depth_scale"`` in recording.json); None = the rig's
    depth_scale: float | None = None

    def depth_m(self, scale: float) -> np.ndarray:
        """Depth in metres, float32 (H, W); NaN where there is no measurement. ``scale`` (the rig's
        metres per unit) is used unless the recording states its own ``depth_scale``."""
        if self.depth is None:
            raise InputError("the recording has no depth map", self.folder)
        if self.depth_scale is not None:
            scale = self.depth_scale
        from ..geometry.depth import to_metres

        return to_metres(self.depth, scale)

    @classmethod
    def load(cls, folder: str | Path, rig: Rig | None = None,
             while_decoding: Callable[[], Any] | None = None) -> "Recording":
        """Read a recording folder; with ``rig``, check it against the rig (names and sizes).
        ``while_decoding``: see :func:`read_images`."""
        folder = Path(folder)
        if folder.is_file() and folder.name == MANIFEST:  # the manifest itself was given
            folder = folder.parent
        manifest = folder / MANIFEST
        check_input_folder(folder, "recording folder")
        if not os.path.lexists(manifest):
            raise InputError(f"not a recording folder (no {MANIFEST})", folder)
        m = read_json(manifest, MANIFEST)
        entries = manifest_entries(m, manifest)
        paths: dict[str, Path] = {}
        images: dict[str, np.ndarray] = {}
        for name, p in entries.items():  # names and paths checked before any image is read
            if rig is not None and name is not None and name not in rig.names:
                raise InputError(f"images.{name}: camera '{name}' is not in the rig ({', '.join(rig.names)})",
                                 manifest)
            what = "depth map" if name is None else f"image of camera '{name}'"
            check_input_file(p, f"{what} listed in {MANIFEST}")
        decoded = read_images(list(entries.values()), while_decoding)
        for (name, p), img in zip(entries.items(), decoded):
            if name is not None:
                images[name] = img
                paths[name] = p
        depth = None
        if None in entries:
            p = entries[None]
            depth = decoded[list(entries).index(None)]
            paths["depth"] = p
            if depth.ndim != 2:
                raise InputError(f"depth map must be single-channel, got shape {depth.shape}", p)
            if depth.dtype.kind not in "uif":
                raise InputError(f"depth map must hold real numbers, got dtype {depth.dtype}", p)
        extra = {k: v for k, v in m.items() if k not in ("depth", "images", "depth_scale")}
        ds = m.get("depth_scale")  # checked by manifest_entries
        rec = cls(folder, depth, images, paths, extra, None if ds is None else float(ds))
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
            d = np.asarray(self.depth, dtype=np.float64)
            with np.errstate(invalid="ignore"):
                if not np.any(np.isfinite(d) & (d > 0)):
                    raise InputError("depth map is empty (no pixel has a finite depth > 0)", p)

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
        if self.depth_scale is not None:
            m["depth_scale"] = self.depth_scale
        m.update(self.extra)
        atomic_write_text(folder / MANIFEST, json.dumps(m, indent=2) + "\n")


def read_images(paths: list[Path], while_decoding: Callable[[], Any] | None = None) -> list[np.ndarray]:
    """:func:`~.imageio.read_image` of every path: the files and headers are checked one by one,
    then the pixels are decoded in parallel threads. A refused file or header raises its
    :class:`InputError` before any pixel is decoded (validation before the expensive work); a
    decoding error, the first failing path in list order.

    Why: the decoders (OpenCV's PNG, ``np.fromfile``, imagecodecs) release the GIL, so a 4K PNG
    and a hyperspectral cube decode side by side instead of one after the other.
    ``while_decoding()`` is called before the decoders finish -- alongside them when more than one
    thread decodes -- and not at all if a header is refused: GIL-bound work placed there
    (``plantreg register`` loads Open3D's extension, long with the GIL held) runs while the
    decoders need no GIL. Threads: at most ``OMP_NUM_THREADS`` when set (``plantreg batch`` gives
    each worker process its share of the cores), else the cores this process may use.
    """
    # headers first, in order (Python work: serial anyway); the first refused one raises here
    decoders: list[Callable[[], np.ndarray]] = [image_decoder(p) for p in paths]
    threads = min(len(decoders), _thread_budget())
    if threads <= 1:
        if while_decoding is not None:
            while_decoding()
        out = [d() for d in decoders]
    else:
        from concurrent.futures import ThreadPoolExecutor

        # the largest files first: they bound the wall time
        order = sorted(range(len(decoders)), key=lambda i: -_file_size(decoders[i].pixel_file))
        with ThreadPoolExecutor(threads, thread_name_prefix="plantreg-read") as ex:
            futures = {i: ex.submit(decoders[i]) for i in order}
            try:
                if while_decoding is not None:
                    while_decoding()
                out = [futures[i].result() for i in range(len(decoders))]
            except BaseException:
                for f in futures.values():
                    f.cancel()
                raise
    return out


def _thread_budget() -> int:
    try:
        n = int(os.environ.get("OMP_NUM_THREADS", "0"))
    except ValueError:
        n = 0
    if n > 0:
        return n
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):  # not on Linux
        return os.cpu_count() or 1


def _file_size(path: Path) -> int:
    try:
        return Path(path).stat().st_size
    except OSError:
        return 0


def recording_inputs(folder: str | Path) -> list[Path]:
    """What registering the recording in ``folder`` reads, without reading any image: the
    folder, its ``recording.json`` and every file listed there (an ENVI header with its data
    files). For output checks: an output must never replace one of them. A manifest that cannot
    be read gives the folder and the manifest only (reading the recording names the problem)."""
    folder = Path(folder)
    if folder.name == MANIFEST:
        folder = folder.parent
    out = [folder, folder / MANIFEST]
    try:
        entries = manifest_entries(read_json(folder / MANIFEST, MANIFEST), folder / MANIFEST)
    except InputError:
        return out
    for p in entries.values():
        out.append(p)
        if p.suffix.lower() == ".hdr" and "\x00" not in str(p):
            out += [p.with_suffix(""), *p.parent.glob(glob.escape(p.stem) + ".*")]
    return out


def manifest_entries(m: Any, manifest: Path) -> dict[str | None, Path]:
    """Camera name (None for the depth map) -> path, from ``recording.json``'s content. Types and
    names are checked here (a null or a number is named as such, not reported as a missing file
    called "None"). Paths are relative to the folder; absolute ones and ones leading out of it
    (``../x``) are accepted (docs/errors.md: a local tool reads what its user points it at)."""
    from .. import validate as v

    if not isinstance(m, dict):
        raise InputError("expected {\"depth\": FILE, \"images\": {CAMERA: FILE}} at the top level", manifest)
    imgs = m.get("images", {})
    if not isinstance(imgs, dict):
        raise InputError(f"\"images\" must be an object {{CAMERA: FILE}}, got {v.show(imgs)}", manifest)
    out: dict[str | None, Path] = {}
    try:
        for name, rel in imgs.items():
            v.camera_name(name, "images key")
            if not isinstance(rel, str) or not rel:
                raise ValueError(f"images.{name} must be a file name (a non-empty string), got {v.show(rel)}")
            out[name] = manifest.parent / rel
        v.unique_names([n for n in out if n is not None], "images")
        dep = m.get("depth")
        if dep is not None and dep != "":  # null or "" = no depth map
            if not isinstance(dep, str):
                raise ValueError(f"depth must be a file name (a non-empty string) or null, got {v.show(dep)}")
            out[None] = manifest.parent / dep
        if m.get("depth_scale") is not None:
            v.depth_scale(m["depth_scale"], "depth_scale")
    except ValueError as e:
        raise InputError(str(e), manifest) from None
    return out


def _write_any(path: Path, img: np.ndarray) -> None:
    from ..io.imageio import atomic_path, write_png, write_tiff

    s = path.suffix.lower()
    if s == ".npy":
        with atomic_path(path) as tmp:
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
