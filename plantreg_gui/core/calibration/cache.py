"""Detections kept in the session folder (``detections.json``), so that a re-run, a
recalibration after excluding views and the wizard's resume do not detect again.

One entry per image, ``"POSE:CAMERA"`` -> ``{"key": ..., "detection": ...}``. The key holds
everything the result depends on: the image file (path relative to the session, size,
modification time in ns, BLAKE2b of its bytes), the board, the image's detection options, the
polarity and modality used, and :data:`~.detect.DETECT_VERSION`. Any change to one of them
misses the cache and the image is detected again. The file is written atomically; a session
folder that cannot be written (read-only media, permissions) simply has no cache, and a
missing, corrupt or foreign ``detections.json`` is ignored (never an error: it is only a cache).
"""

from __future__ import annotations

import hashlib
import json
import stat
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import PlantregError
from ..io.imageio import atomic_write_text
from .detect import DETECT_VERSION, Detection, DetectOptions

CACHE_FILE = "detections.json"
_FORMAT = "plantreg detections"


def image_key(session, pose: str, camera: str, options: DetectOptions) -> dict[str, Any] | None:
    """What a detection of (``pose``, ``camera``) depends on, or None when the image cannot be
    examined (missing, unreadable: detection reports that itself)."""
    path = session.pose(pose).images.get(camera)
    if path is None:
        return None
    try:
        st = Path(path).stat()
        if not stat.S_ISREG(st.st_mode):  # a FIFO would block the read: the reader names it
            return None
        h = hashlib.blake2b(digest_size=16)
        with open(path, "rb") as f:
            for block in iter(lambda: f.read(1 << 20), b""):
                h.update(block)
    except OSError:
        return None
    try:
        rel = str(Path(path).relative_to(session.folder))
    except ValueError:
        rel = str(path)
    inverted = options.invert if options.invert is not None else session.default_inverted(camera)
    return {"file": rel, "size": st.st_size, "mtime_ns": st.st_mtime_ns, "blake2b": h.hexdigest(),
            "board": session.board.to_dict(), "options": options.to_dict(), "inverted": bool(inverted),
            "modality": session.cameras.get(camera), "version": DETECT_VERSION}


def detection_to_dict(d: Detection) -> dict[str, Any]:
    return {"status": d.status, "reason": d.reason,
            "corners": None if d.corners is None else np.asarray(d.corners, float).round(4).tolist(),
            "ids": None if d.ids is None else np.asarray(d.ids).astype(int).tolist(),
            "image_size": list(d.image_size), "inverted": bool(d.inverted),
            "variant": d.variant, "conversion": d.conversion, "scale": float(d.scale)}


def detection_from_dict(d: dict[str, Any], pose: str, camera: str, path: Path | None,
                        options: DetectOptions) -> Detection:
    corners = None if d.get("corners") is None else np.asarray(d["corners"], np.float32).reshape(-1, 2)
    ids = None if d.get("ids") is None else np.asarray(d["ids"], np.int32)
    return Detection(pose, camera, str(d["status"]), str(d.get("reason", "")), corners, ids,
                     tuple(int(v) for v in d["image_size"]), bool(d["inverted"]), path, options,
                     str(d.get("variant", "")), str(d.get("conversion", "")), float(d.get("scale", 1.0)))


class DetectionCache:
    """The ``detections.json`` of one session (see the module docstring)."""

    def __init__(self, session) -> None:
        self.session = session
        self.path = Path(session.folder) / CACHE_FILE
        self.entries: dict[str, dict[str, Any]] = {}
        self.dirty = False
        try:
            d = json.loads(self.path.read_text(encoding="utf-8"))
            if isinstance(d, dict) and d.get("format") == _FORMAT and isinstance(d.get("images"), dict):
                self.entries = d["images"]
        except (OSError, ValueError, UnicodeDecodeError):
            pass

    def get(self, pose: str, camera: str, key: dict[str, Any] | None, options: DetectOptions) -> Detection | None:
        """The cached detection of the image if ``key`` matches, else None."""
        e = self.entries.get(f"{pose}:{camera}")
        if key is None or not isinstance(e, dict) or e.get("key") != key:
            return None
        try:
            return detection_from_dict(e["detection"], pose, camera, self.session.pose(pose).images.get(camera),
                                       options)
        except (KeyError, TypeError, ValueError):
            return None

    def put(self, det: Detection, key: dict[str, Any] | None) -> None:
        if key is None or det.status == "missing":
            return
        self.entries[f"{det.pose}:{det.camera}"] = {"key": key, "detection": detection_to_dict(det)}
        self.dirty = True

    def save(self) -> bool:
        """Write the file atomically if anything changed; False when the folder is not writable."""
        if not self.dirty:
            return True
        known = {f"{p.name}:{c}" for p in self.session.poses for c in p.images}
        images = {k: v for k, v in sorted(self.entries.items()) if k in known}
        try:
            atomic_write_text(self.path, json.dumps({"format": _FORMAT, "version": DETECT_VERSION,
                                                     "images": images}) + "\n")
        except (OSError, PlantregError):  # a read-only session: no cache, no error
            return False
        self.dirty = False
        return True
