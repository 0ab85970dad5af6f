"""The rig file (``plantreg.rig`` JSON, version 1): cameras, depth camera, region of interest.

```json
{"format": "plantreg.rig", "version": 1,
 "depth": {"camera": "ir", "scale": 0.001},
 "roi": {"min": [-0.45, -0.45, 0.30], "max": [0.45, 0.45, 1.17]},
 "cameras": [{"name": "ir", "modality": "infrared", "width": 640, "height": 576,
              "K": [[504, 0, 320], [0, 504, 288], [0, 0, 1]], "dist": [0.02, -0.01, 0, 0, 0],
              "R": [[1, 0, 0], [0, 1, 0], [0, 0, 1]], "t": [0, 0, 0]}]}
```

``depth.camera`` names the camera whose pixels the depth map is aligned with; ``depth.scale``
is metres per depth unit; ``roi`` is a box in the rig frame whose ``max`` z is the ground
plane. Unknown keys (top level and per camera) are kept on save.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .camera import Camera
from ..errors import InputError
from ..io.imageio import atomic_write_text, read_json

FORMAT = "plantreg.rig"
VERSION = 1


@dataclass
class Rig:
    """Cameras posed in the rig frame (= the depth camera's frame).

    ``roi_min``/``roi_max`` (3,) metres in the rig frame; ``roi_max[2]`` is the ground plane.
    ``depth_camera`` is None for a rig without a depth camera (it can be calibrated, not registered).
    """

    cameras: list[Camera]
    depth_camera: str | None = None
    depth_scale: float = 0.001
    roi_min: np.ndarray = field(default_factory=lambda: np.array([-0.5, -0.5, 0.2]))
    roi_max: np.ndarray = field(default_factory=lambda: np.array([0.5, 0.5, 1.2]))
    extra: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.roi_min = np.asarray(self.roi_min, dtype=np.float64).reshape(3)
        self.roi_max = np.asarray(self.roi_max, dtype=np.float64).reshape(3)

    @property
    def names(self) -> list[str]:
        return [c.name for c in self.cameras]

    @property
    def ground_z(self) -> float:
        """Ground plane z in the rig frame (the ROI's max z)."""
        return float(self.roi_max[2])

    def camera(self, name: str) -> Camera:
        for c in self.cameras:
            if c.name == name:
                return c
        raise InputError(f"unknown camera '{name}'; the rig has {', '.join(self.names) or 'no cameras'}")

    def depth(self) -> Camera:
        """The depth camera; raises :class:`InputError` if the rig has none."""
        if self.depth_camera is None:
            raise InputError("the rig has no depth camera (\"depth\": {\"camera\": ...} is missing)")
        return self.camera(self.depth_camera)

    # ------------------------------------------------------------------ (de)serialisation
    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {"format": FORMAT, "version": VERSION}
        if self.depth_camera is not None:
            d["depth"] = {"camera": self.depth_camera, "scale": self.depth_scale}
        d["roi"] = {"min": self.roi_min.tolist(), "max": self.roi_max.tolist()}
        d["cameras"] = [c.to_dict() for c in self.cameras]
        for k, v in self.extra.items():
            d.setdefault(k, v)
        return d

    @classmethod
    def from_dict(cls, d: Any, path: str | Path | None = None) -> "Rig":
        """Build from the rig file's JSON; every type and sanity bound (:mod:`.validate`) is
        checked here, up front, and a failure names ``path`` and the key (``cameras[2].width``)."""
        from .. import validate as v

        def bad(msg: str) -> InputError:
            return InputError(msg, path)

        if not isinstance(d, dict):
            raise bad("not a rig file (the top level must be a JSON object)")
        if d.get("format", FORMAT) != FORMAT:
            raise bad(f"format is {v.show(d.get('format'))}, expected '{FORMAT}'")
        version = d.get("version", VERSION)
        if not v.is_number(version) or not np.isfinite(version) or not float(version).is_integer():
            raise bad(f"version must be a whole number, got {v.show(version)}")
        if version > VERSION:
            raise bad(f"rig file version {d.get('version')} is newer than this plantreg reads ({VERSION})")
        cams = d.get("cameras")
        if not isinstance(cams, list) or not cams:
            raise bad("the rig has no cameras (\"cameras\" must be a non-empty list)")
        cameras = []
        try:
            for i, c in enumerate(cams):
                cameras.append(Camera.from_dict(c, f"cameras[{i}]"))
            names = [c.name for c in cameras]
            v.unique_names(names)
        except ValueError as e:
            raise bad(str(e)) from None
        depth = d.get("depth")
        depth_camera, scale = None, 0.001
        if depth is not None:
            if not isinstance(depth, dict) or "camera" not in depth:
                raise bad("\"depth\" must be {\"camera\": NAME, \"scale\": METRES_PER_UNIT}")
            if not isinstance(depth["camera"], str):
                raise bad(f"depth.camera must be a camera name (a string), got {v.show(depth['camera'])}")
            depth_camera = depth["camera"]
            if depth_camera not in names:
                raise bad(f"depth camera '{depth_camera}' is not among the cameras ({', '.join(names)})")
            try:
                scale = v.depth_scale(depth.get("scale", 0.001), "depth.scale")
            except ValueError as e:
                raise bad(str(e)) from None
        roi = d.get("roi", {})
        if not isinstance(roi, dict):
            raise bad(f"roi must be {{\"min\": [x, y, z], \"max\": [x, y, z]}}, got {v.show(roi)}")
        try:
            roi_min = v.number_array(roi.get("min", [-0.5, -0.5, 0.2]), "roi.min", (3,), " [x, y, z] in metres")
            roi_max = v.number_array(roi.get("max", [0.5, 0.5, 1.2]), "roi.max", (3,), " [x, y, z] in metres")
        except ValueError as e:
            raise bad(str(e)) from None
        if not np.all(roi_min < roi_max):
            raise bad("roi min must be below max in x, y and z")
        if np.abs(np.concatenate([roi_min, roi_max])).max() > v.MAX_TRANSLATION_M:
            raise bad(f"roi reaches beyond {v.MAX_TRANSLATION_M:g} m from the depth camera (metres: millimetres "
                      "by mistake?)")
        extra = {k: val for k, val in d.items() if k not in ("format", "version", "depth", "roi", "cameras")}
        return cls(cameras, depth_camera, scale, roi_min, roi_max, extra)

    @classmethod
    def load(cls, path: str | Path) -> "Rig":
        path = Path(path)
        return cls.from_dict(read_json(path, "rig file"), path)

    def save(self, path: str | Path) -> None:
        """Write atomically (temp file + rename)."""
        atomic_write_text(path, json.dumps(self.to_dict(), indent=2) + "\n")
