"""A capture session: ``session.json`` plus one sub-folder per board pose.

Binding format::

    {"board": {"type": "chessboard", "columns": 15, "rows": 8, "square_size": 0.0185},
     "depth": {"camera": "ir", "scale": 0.001},
     "cameras": {"ir": {"modality": "infrared"}, "thermal": {"modality": "thermal"}},
     "review": {"excluded": ["pose_03:thermal"],
                "options": {"pose_05:thermal": {"invert": true, "enhance": true}}}}

Each pose folder holds one image per camera named after the camera (``ir.png``,
``thermal.tif``, ...) and, with a depth camera, ``depth.<ext>``. A camera may be missing from a
pose. ``columns``/``rows`` count inner corners. ``depth`` is optional. ``review`` is written by
the wizard so that a session reopens where it was left: excluded views and per-image detection
options, keys ``"POSE:CAMERA"``. Unknown top-level keys are kept on save.
"""

from __future__ import annotations

import json
import shutil
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..camera import modality
from ..errors import InputError
from ..io.imageio import IMAGE_SUFFIXES, atomic_write_text, has_write_bits, read_json
from .board import Board

SESSION_FILE = "session.json"
DEPTH_STEM = "depth"

#: Detection polarity default per modality (``Modality.inverted_board``): a heated board seen by
#: a thermal camera glows where the print is black, so the image is a photographic negative.
INVERTED_MODALITIES = tuple(m.name for m in modality.MODALITIES if m.inverted_board)



CAMERA_META_KEYS = ("units", "bands")


def camera_meta_from_dict(c: dict[str, Any], what: str, path) -> dict[str, Any]:
    """The ``units`` (str) and ``bands`` (list of nm) of a camera entry, checked."""
    meta: dict[str, Any] = {}
    if c.get("units") is not None:
        if not isinstance(c["units"], str):
            raise InputError(f"{what}: \"units\" must be a string (e.g. \"degC\")", path)
        meta["units"] = c["units"]
    if c.get("intrinsics") is not None:  # a rig file whose intrinsics this camera keeps (calibrate.py)
        if not isinstance(c["intrinsics"], str) or not c["intrinsics"]:
            raise InputError(f"{what}: \"intrinsics\" must be the path of a rig file", path)
        meta["intrinsics"] = c["intrinsics"]
    if c.get("bands") is not None:
        b = c["bands"]
        if not isinstance(b, list) or not b or not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in b):
            raise InputError(f"{what}: \"bands\" must be a list of band centres in nm", path)
        meta["bands"] = [float(x) for x in b]
    return meta

@dataclass
class Pose:
    """One board pose: ``images`` camera name -> file, ``depth`` the depth map file or None."""

    name: str
    images: dict[str, Path]
    depth: Path | None = None

    @property
    def folder(self) -> Path | None:
        paths = list(self.images.values()) + ([self.depth] if self.depth else [])
        return paths[0].parent if paths else None


def view_key(pose: str, camera: str) -> str:
    """``"POSE:CAMERA"``, the key of one image in ``review`` and on the command line."""
    return f"{pose}:{camera}"


def parse_view_key(key: str) -> tuple[str, str]:
    pose, sep, cam = str(key).rpartition(":")
    if not sep or not pose or not cam:
        raise ValueError(f"'{key}' is not POSE:CAMERA")
    return pose, cam


def _find_image(folder: Path, stem: str) -> Path | None:
    # not only regular files: a FIFO or device named ir.png is reported by the reader as such,
    # not silently treated as a missing image
    hits = sorted(p for p in folder.iterdir()
                  if not p.is_dir() and p.stem == stem and p.suffix.lower() in IMAGE_SUFFIXES)
    return hits[0] if hits else None


@dataclass
class Session:
    """A capture session in ``folder``.

    ``cameras`` name -> modality (order kept: the first camera is the reference when there is no
    depth camera). ``depth_camera`` names the camera whose pixels the depth maps are aligned with.
    ``poses`` sorted by name. ``review`` = ``{"excluded": [keys], "options": {key: {...}}}``.
    """

    folder: Path
    board: Board
    cameras: dict[str, str]
    depth_camera: str | None = None
    depth_scale: float = 0.001
    poses: list[Pose] = field(default_factory=list)
    review: dict[str, Any] = field(default_factory=dict)
    extra: dict[str, Any] = field(default_factory=dict)
    #: per camera, what the rig file carries beside the geometry: ``units`` (str, e.g. "degC") and
    #: ``bands`` (band centres in nm, for multi-band cameras); copied into the calibrated rig
    camera_meta: dict[str, dict[str, Any]] = field(default_factory=dict)

    # ------------------------------------------------------------------ queries
    @property
    def path(self) -> Path:
        return Path(self.folder) / SESSION_FILE

    def inputs(self) -> list[Path]:
        """What calibrating reads: the folder, ``session.json``, every image and depth map (an
        output must never replace one: docs/errors.md, "Paths, names and outputs")."""
        return [Path(self.folder), self.path] + [Path(f) for pose in self.poses
                                                 for f in [*pose.images.values(), *([pose.depth] if pose.depth else [])]]

    @property
    def camera_names(self) -> list[str]:
        return list(self.cameras)

    def pose(self, name: str) -> Pose:
        for p in self.poses:
            if p.name == name:
                return p
        raise InputError(f"the session has no pose '{name}'", self.folder)

    def default_inverted(self, camera: str) -> bool:
        """The board polarity assumed for ``camera`` when not set: inverted for thermal cameras."""
        return modality.inverted_board(self.cameras.get(camera))

    # ------------------------------------------------------------------ review state
    def excluded(self) -> set[tuple[str, str]]:
        out = set()
        for k in self.review.get("excluded", []):
            try:
                out.add(parse_view_key(k))
            except ValueError:
                continue
        return out

    def set_excluded(self, views: set[tuple[str, str]] | frozenset) -> None:
        self.review["excluded"] = sorted(view_key(p, c) for p, c in views)

    def detect_options(self) -> dict[tuple[str, str], Any]:
        """Per-image detection options stored in ``review`` -> ``{(pose, cam): DetectOptions}``."""
        from .detect import DetectOptions

        out = {}
        for k, v in dict(self.review.get("options", {})).items():
            try:
                out[parse_view_key(k)] = DetectOptions.from_dict(v)
            except (ValueError, TypeError, AttributeError):
                continue
        return out

    def set_detect_options(self, pose: str, camera: str, options: Any | None) -> None:
        """Store (or with None remove) the detection options of one image."""
        opts = self.review.setdefault("options", {})
        if options is None:
            opts.pop(view_key(pose, camera), None)
        else:
            opts[view_key(pose, camera)] = options.to_dict()

    # ------------------------------------------------------------------ load / save
    @classmethod
    def load(cls, folder: str | Path) -> "Session":
        """Read ``folder/session.json`` and discover the pose folders.

        Raises :class:`InputError` naming the file for a missing or malformed session.
        """
        folder = Path(folder)
        if folder.is_file() and folder.name == SESSION_FILE:
            folder = folder.parent
        path = folder / SESSION_FILE
        if not folder.is_dir():
            raise InputError("is a file, not a session folder (open the folder that holds session.json)"
                             if folder.exists() else "session folder not found", folder)
        if not path.is_file():
            raise InputError(f"not a calibration session (no {SESSION_FILE})", folder)
        from ..validate import camera_name, show, unique_names

        d = read_json(path, SESSION_FILE)
        if not isinstance(d, dict):
            raise InputError("the top level must be a JSON object", path)
        try:
            board = Board.from_dict(d.get("board"))
        except ValueError as e:
            raise InputError(str(e), path) from None
        cams = d.get("cameras")
        if not isinstance(cams, dict) or not cams:
            raise InputError("\"cameras\" must be a non-empty object {NAME: {\"modality\": ...}}", path)
        cameras: dict[str, str] = {}
        try:
            for name in cams:
                camera_name(name, "cameras key")
            unique_names(list(cams))
        except ValueError as e:
            raise InputError(str(e), path) from None
        camera_meta: dict[str, dict[str, Any]] = {}
        for name, c in cams.items():
            if not isinstance(c, dict):
                raise InputError(f"camera '{name}' must be an object {{\"modality\": ...}}", path)
            if ":" in str(name) or str(name) == DEPTH_STEM:
                raise InputError(f"camera name '{name}' is not allowed (no ':' and not '{DEPTH_STEM}')", path)
            cameras[str(name)] = modality.canonical(str(c.get("modality", "unknown")))
            meta = camera_meta_from_dict(c, f"camera '{name}'", path)
            if meta:
                camera_meta[str(name)] = meta
        depth_camera, depth_scale = None, 0.001
        if d.get("depth") is not None:
            dd = d["depth"]
            if not isinstance(dd, dict) or "camera" not in dd:
                raise InputError("\"depth\" must be {\"camera\": NAME, \"scale\": METRES_PER_UNIT}", path)
            if not isinstance(dd["camera"], str):
                raise InputError(f"depth.camera must be a camera name (a string), got {show(dd['camera'])}", path)
            depth_camera = dd["camera"]
            if depth_camera not in cameras:
                raise InputError(f"depth camera '{depth_camera}' is not among the cameras ({', '.join(cameras)})", path)
            from ..validate import depth_scale as check_scale

            try:
                depth_scale = check_scale(dd.get("scale", 0.001), "depth.scale")
            except ValueError as e:
                raise InputError(str(e), path) from None
        review = d.get("review", {}) if d.get("review") is not None else {}
        if not isinstance(review, dict):
            raise InputError("\"review\" must be an object {\"excluded\": [\"POSE:CAMERA\", ...], \"options\": {...}}", path)
        if not isinstance(review.get("excluded", []), list):
            raise InputError("review.excluded must be a list of \"POSE:CAMERA\" strings", path)
        if not isinstance(review.get("options", {}), dict):
            raise InputError("review.options must be an object {\"POSE:CAMERA\": {...}}", path)
        extra = {k: v for k, v in d.items() if k not in ("board", "depth", "cameras", "review")}
        s = cls(folder, board, cameras, depth_camera, depth_scale, [], review, extra, camera_meta)
        s.rescan()
        return s

    def rescan(self) -> None:
        """Re-discover the pose folders (sub-folders holding at least one camera image)."""
        poses = []
        for sub in sorted(p for p in Path(self.folder).iterdir() if p.is_dir() and not p.name.startswith(".")):
            images = {}
            for cam in self.cameras:
                f = _find_image(sub, cam)
                if f is not None:
                    images[cam] = f
            depth = _find_image(sub, DEPTH_STEM) if self.depth_camera else None
            if images:
                poses.append(Pose(sub.name, images, depth))
        self.poses = poses

    @classmethod
    def create(cls, folder: str | Path, board: Board, cameras: dict[str, str],
               depth_camera: str | None = None, depth_scale: float = 0.001) -> "Session":
        """Make a new (empty) session in ``folder`` and write its ``session.json``."""
        folder = Path(folder)
        if (folder / SESSION_FILE).exists():
            raise InputError(f"a session already exists here ({SESSION_FILE}); open it instead", folder)
        if not cameras:
            raise InputError("a session needs at least one camera", folder)
        if depth_camera is not None and depth_camera not in cameras:
            raise InputError(f"depth camera '{depth_camera}' is not among the cameras ({', '.join(cameras)})", folder)
        folder.mkdir(parents=True, exist_ok=True)
        cameras = {n: modality.canonical(m) for n, m in cameras.items()}
        s = cls(folder, board, cameras, depth_camera, float(depth_scale), [], {})
        s.save()
        s.rescan()
        return s

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {"board": self.board.to_dict()}
        if self.depth_camera is not None:
            d["depth"] = {"camera": self.depth_camera, "scale": self.depth_scale}
        d["cameras"] = {n: {"modality": m, **self.camera_meta.get(n, {})} for n, m in self.cameras.items()}
        d["review"] = self.review
        for k, v in self.extra.items():
            d.setdefault(k, v)
        return d

    def writable(self) -> bool:
        """Whether the session folder may be written without being asked: it has write bits
        (also for root, who may write anyway). Derived files (``detections.json``) and the
        wizard's review state follow this; an explicit save does not ask."""
        return has_write_bits(self.folder)

    def save(self) -> None:
        """Write ``session.json`` atomically (board, cameras, depth, review)."""
        atomic_write_text(self.path, json.dumps(self.to_dict(), indent=2) + "\n")

    # ------------------------------------------------------------------ editing
    def add_pose_from_folder(self, path: str | Path, name: str | None = None) -> Pose:
        """Copy the images of one pose (files named after the cameras, plus ``depth.*``) from
        ``path`` into a new pose folder of the session; returns the new pose.

        Raises :class:`InputError` if ``path`` holds no image named after a camera.
        """
        src = Path(path)
        if not src.is_dir():
            raise InputError("pose folder not found", src)
        found = {cam: _find_image(src, cam) for cam in self.cameras}
        found = {k: v for k, v in found.items() if v is not None}
        if not found:
            raise InputError(
                f"no image named after a camera ({', '.join(self.cameras)}; e.g. {next(iter(self.cameras))}.png)", src
            )
        depth = _find_image(src, DEPTH_STEM) if self.depth_camera else None
        existing = {p.name for p in self.poses} | {p.name for p in Path(self.folder).iterdir() if p.is_dir()}
        if name is None:
            name = src.name if src.name not in existing and not src.name.startswith(".") else None
        if name is None or name in existing:
            i = len(self.poses) + 1
            while f"pose_{i:02d}" in existing:
                i += 1
            name = f"pose_{i:02d}"
        dst = Path(self.folder) / name
        tmp = Path(self.folder) / f".{name}.part"
        shutil.rmtree(tmp, ignore_errors=True)
        tmp.mkdir(parents=True)
        try:
            for f in list(found.values()) + ([depth] if depth else []):
                shutil.copy2(f, tmp / f.name)
                if f.suffix.lower() == ".hdr":  # ENVI: the data file sits beside the header
                    for data in f.parent.glob(f.stem + ".*"):
                        if data.suffix.lower() not in (".hdr",) and data != f:
                            shutil.copy2(data, tmp / data.name)
            tmp.rename(dst)
        except BaseException:
            shutil.rmtree(tmp, ignore_errors=True)
            raise
        self.rescan()
        return self.pose(name)

    def remove_pose(self, name: str) -> None:
        """Delete a pose folder and its review entries (the session file is saved)."""
        pose = self.pose(name)
        folder = Path(self.folder) / pose.name
        shutil.rmtree(folder)
        self.review["excluded"] = [k for k in self.review.get("excluded", []) if not k.startswith(f"{name}:")]
        opts = self.review.get("options", {})
        for k in [k for k in opts if k.startswith(f"{name}:")]:
            opts.pop(k)
        self.rescan()
        self.save()
