"""The landmarks file (``plantreg.landmarks`` JSON, version 1): the same physical points clicked
in the depth camera and in other cameras, per recording.

```json
{"format": "plantreg.landmarks", "version": 1,
 "recordings": {"recordings/01grapevine": {"points": [
    {"depth_uv": [412.0, 233.5], "cameras": {"thermal": [301.2, 118.0], "hyperspectral": [260.5, 402.0]},
     "note": "leaf tip"}]}}}
```

Recording keys are folder paths relative to the landmarks file (absolute paths are kept as they
are). Pixels are ``[u, v]`` = (column, row) with pixel centres at integer coordinates, as
everywhere in plantreg. ``depth_uv`` is a pixel of the rig's depth camera; ``cameras`` maps other
camera names to the pixel of the same point in that camera. Unknown keys are kept on save.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError
from ..io.imageio import atomic_write_text, read_json
from ..io.paths import check_input_folder

FORMAT = "plantreg.landmarks"
VERSION = 1
#: The most points a landmarks file may hold (all recordings together).
MAX_POINTS = 10000


@dataclass
class Landmark:
    """One point: ``depth_uv`` (2,) in the depth camera, ``cameras[name]`` (2,) in other cameras."""

    depth_uv: np.ndarray
    cameras: dict[str, np.ndarray] = field(default_factory=dict)
    note: str = ""
    extra: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.depth_uv = np.asarray(self.depth_uv, dtype=np.float64).reshape(2)
        self.cameras = {str(k): np.asarray(v, dtype=np.float64).reshape(2) for k, v in self.cameras.items()}

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {"depth_uv": [float(x) for x in self.depth_uv],
                             "cameras": {k: [float(x) for x in v] for k, v in self.cameras.items()}}
        if self.note:
            d["note"] = self.note
        for k, v in self.extra.items():
            d.setdefault(k, v)
        return d


@dataclass
class LandmarkSet:
    """Landmarks per recording. ``recordings`` maps the key as written in the file (a folder path
    relative to ``base``, the landmarks file's folder) to its points."""

    recordings: dict[str, list[Landmark]] = field(default_factory=dict)
    base: Path | None = None
    path: Path | None = None
    extra: dict[str, Any] = field(default_factory=dict)
    recording_extra: dict[str, dict[str, Any]] = field(default_factory=dict)

    def folder(self, key: str) -> Path:
        """The recording folder of ``key`` (relative keys resolve against the landmarks file's folder)."""
        p = Path(key)
        return p if p.is_absolute() or self.base is None else self.base / p

    @property
    def camera_names(self) -> list[str]:
        """Cameras (other than the depth camera) that have at least one landmark, sorted."""
        return sorted({c for pts in self.recordings.values() for lm in pts for c in lm.cameras})

    def count(self) -> int:
        return sum(len(p) for p in self.recordings.values())

    # ------------------------------------------------------------------ (de)serialisation
    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {"format": FORMAT, "version": VERSION, "recordings": {}}
        for key, pts in self.recordings.items():
            r: dict[str, Any] = {"points": [lm.to_dict() for lm in pts]}
            for k, v in self.recording_extra.get(key, {}).items():
                r.setdefault(k, v)
            d["recordings"][key] = r
        for k, v in self.extra.items():
            d.setdefault(k, v)
        return d

    def save(self, path: str | Path) -> None:
        """Write atomically (a crash leaves the old file or the new one, never half of one)."""
        atomic_write_text(Path(path), json.dumps(self.to_dict(), indent=1) + "\n")

    @classmethod
    def from_dict(cls, d: Any, path: str | Path | None = None, base: str | Path | None = None) -> "LandmarkSet":
        """Parse and validate; raises :class:`InputError` (one line, naming ``path``)."""

        def bad(msg: str) -> InputError:
            return InputError(msg, path)

        if not isinstance(d, dict):
            raise bad("not a landmarks file (the top level must be a JSON object)")
        if d.get("format") != FORMAT:
            raise bad(f"format is {d.get('format')!r}, expected '{FORMAT}'")
        version = d.get("version")
        if isinstance(version, bool) or not isinstance(version, (int, float)) or not float(version).is_integer():
            raise bad(f"version must be a whole number, got {version!r}")
        if version > VERSION or version < 1:
            raise bad(f"landmarks file version {version} is not one this plantreg reads ({VERSION})")
        recs = d.get("recordings")
        if not isinstance(recs, dict):
            raise bad("\"recordings\" must be an object {RECORDING_FOLDER: {\"points\": [...]}}")
        out: dict[str, list[Landmark]] = {}
        rextra: dict[str, dict[str, Any]] = {}
        total = 0
        for key, r in recs.items():
            if not isinstance(r, dict) or not isinstance(r.get("points"), list):
                raise bad(f"recording '{key}': expected {{\"points\": [...]}}")
            total += len(r["points"])
            if total > MAX_POINTS:
                raise bad(f"holds more than {MAX_POINTS} points (at recording '{key}'); landmarks are clicked by "
                          "hand, a few dozen per recording: a file this large is not a landmarks file (and its fit "
                          "would run for hours)")
            pts = []
            for i, p in enumerate(r["points"]):
                where = f"recording '{key}', point {i}"
                if not isinstance(p, dict):
                    raise bad(f"{where}: not an object")
                if "depth_uv" not in p:
                    raise bad(f"{where}: missing \"depth_uv\"")
                duv = _pixel(p["depth_uv"], f"{where}: depth_uv", bad)
                cams = p.get("cameras", {})
                if not isinstance(cams, dict):
                    raise bad(f"{where}: \"cameras\" must be an object {{CAMERA: [u, v]}}")
                cams = {str(k): _pixel(v, f"{where}: camera '{k}'", bad) for k, v in cams.items()}
                note = p.get("note", "")
                if not isinstance(note, str):
                    raise bad(f"{where}: \"note\" must be text")
                extra = {k: v for k, v in p.items() if k not in ("depth_uv", "cameras", "note")}
                pts.append(Landmark(duv, cams, note, extra))
            out[str(key)] = pts
            rextra[str(key)] = {k: v for k, v in r.items() if k != "points"}
        extra = {k: v for k, v in d.items() if k not in ("format", "version", "recordings")}
        return cls(out, Path(base) if base is not None else None, Path(path) if path is not None else None,
                   extra, rextra)

    @classmethod
    def load(cls, path: str | Path, rig: Any = None, check_recordings: bool = False) -> "LandmarkSet":
        """Read a landmarks file. With ``rig``, check camera names (and pixels against image
        sizes); with ``check_recordings``, check that every recording folder has a recording.json."""
        path = Path(path)
        ls = cls.from_dict(read_json(path, "landmarks file"), path, path.parent)
        if rig is not None:
            ls.check(rig)
        if check_recordings:
            ls.check_recordings()
        return ls

    def check(self, rig: Any) -> None:
        """Raise :class:`InputError` naming the file where a landmark does not fit ``rig``:
        unknown cameras, the depth camera used as an "other" camera, pixels outside the image."""
        dname = rig.depth().name
        dcam = rig.depth()
        for key, pts in self.recordings.items():
            for i, lm in enumerate(pts):
                where = f"recording '{key}', point {i}"
                if not dcam.in_image(lm.depth_uv[None])[0]:
                    raise InputError(f"{where}: depth_uv {_fmt(lm.depth_uv)} is outside the depth camera "
                                     f"'{dname}' ({dcam.width}x{dcam.height})", self.path)
                for name, uv in lm.cameras.items():
                    if name == dname:
                        raise InputError(f"{where}: camera '{name}' is the depth camera; its pixel is depth_uv",
                                         self.path)
                    if name not in rig.names:
                        raise InputError(f"{where}: unknown camera '{name}'; the rig has {', '.join(rig.names)}",
                                         self.path)
                    cam = rig.camera(name)
                    if not cam.in_image(uv[None])[0]:
                        raise InputError(f"{where}: pixel {_fmt(uv)} is outside camera '{name}' "
                                         f"({cam.width}x{cam.height})", self.path)

    def check_recordings(self) -> None:
        from .recording import MANIFEST

        for key in self.recordings:
            f = self.folder(key)
            try:
                check_input_folder(f, f"recording '{key}'")
            except InputError as e:
                raise InputError(f"{e.detail} ({f})", self.path) from None
            if not (f / MANIFEST).is_file():
                raise InputError(f"recording '{key}' is not a recording folder (no {MANIFEST} in {f})", self.path)


def _pixel(v: Any, where: str, bad) -> np.ndarray:
    if (not isinstance(v, (list, tuple)) or len(v) != 2
            or not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v)):
        raise bad(f"{where} must be [u, v] (two numbers), got {json.dumps(v)[:40]}")
    if not all(math.isfinite(float(x)) for x in v):
        raise bad(f"{where} must be finite numbers, got {v}")
    return np.array(v, dtype=np.float64)


def _fmt(uv: np.ndarray) -> str:
    return f"[{uv[0]:.1f}, {uv[1]:.1f}]"
