"""What one image's board detection is: its options (:class:`DetectOptions`), its result
(:class:`Detection`: ordered corners and how they were found), the detection variants' names,
the JSON form kept in ``detections.json`` and the figures a report carries
(:func:`detection_summary`). No image processing here: see :mod:`.imageprep` (image -> grey),
:mod:`.corners` (finding and ordering chessboard corners), :mod:`.variants` (what is tried on
one image) and :mod:`.detect` (sessions, the worker pool and the cache).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError
from .board import Board

FOUND, FAILED, MISSING = "found", "failed", "missing"
#: Changes whenever detection can give other results for the same image and options: cached
#: detections (``detections.json``, :class:`~.detect.DetectionCache`) of another version are detected again.
DETECT_VERSION = 5
DETECTORS = ("auto", "classic")
#: What :func:`~.variants.detect_image` tries, in this order, until the whole board is found: the scalar
#: image stretched ("plain"); with its background removed and its local contrast normalised at
#: two scales ("flat", "flat-fine"; :func:`~.imageprep.flatten`); with CLAHE ("clahe"); flattened at twice the
#: size for small, far or steep boards ("fine-2x"); the exhaustive searches ("thorough"); and,
#: for downscaled images, the full-resolution image ("full-res"). On each, the classic detector
#: (image and negative) then the SB detector (:func:`~.corners._find_any`).
VARIANTS = ("plain", "flat", "flat-fine", "clahe", "fine-2x", "thorough", "full-res")
VARIANT_TEXT = {"plain": "plain", "flat": "background removed", "flat-fine": "background removed (fine)",
                "clahe": "CLAHE", "fine-2x": "background removed (fine)", "thorough": "exhaustive search", "full-res": "full resolution",
                "classic": "OpenCV classic"}



@dataclass
class DetectOptions:
    """Per-image detection options.

    ``invert``: board polarity. True = the board appears as a negative (heated board in a thermal
    camera), False = normal print, None = decided by the camera's modality (thermal -> True).
    Detection itself always tries the image and its negative; ``invert`` decides the corner order.
    ``enhance``: apply CLAHE (local contrast) before detection, for faint thermal boards.
    ``detector`` (chessboards): ``"auto"`` = ``findChessboardCornersSB`` with the classic detector
    as a fallback; ``"classic"`` = OpenCV's classic pipeline only (``findChessboardCorners`` +
    ``cornerSubPix`` with an 11 x 11 half-window, as OpenCV's ``stereo_calib`` sample does) --
    kept for comparison with published figures; its large window is biased where foreshortened
    squares are smaller than ~24 px.
    """

    invert: bool | None = None
    enhance: bool = False
    detector: str = "auto"

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {"invert": self.invert, "enhance": bool(self.enhance)}
        if self.detector != "auto":
            d["detector"] = self.detector
        return d

    @classmethod
    def from_dict(cls, d: Any) -> "DetectOptions":
        if not isinstance(d, dict):
            raise ValueError("detection options must be an object")
        inv = d.get("invert")
        det = str(d.get("detector", "auto"))
        if det not in DETECTORS:
            raise ValueError(f"detector must be one of {', '.join(DETECTORS)}")
        return cls(None if inv is None else bool(inv), bool(d.get("enhance", False)), det)


@dataclass
class Detection:
    """Result of one image. ``corners`` (N, 2) float32 in board order (chessboard: all
    ``columns * rows`` corners; ChArUco: the corners found, ids in ``ids`` (N,) int32), None unless
    ``status == "found"``. ``image_size`` (w, h). ``inverted`` = the polarity used for ordering.
    ``path`` the image file (None for in-memory images).

    How the board was found (see :data:`VARIANTS`): ``variant`` the preparation that found it
    ("plain", "flat", ...; "" when nothing was tried), ``conversion`` how the image became a
    scalar ("grey", "16-bit", "float", "palette iron", "colour PC1", "luma", "band mean"),
    ``scale`` the working scale (2 = upscaled twice, 0.46 = downscaled; corners are always in
    image pixels)."""

    pose: str
    camera: str
    status: str
    reason: str
    corners: np.ndarray | None
    ids: np.ndarray | None
    image_size: tuple[int, int]
    inverted: bool
    path: Path | None = None
    options: DetectOptions = field(default_factory=DetectOptions)
    variant: str = ""
    conversion: str = ""
    scale: float = 1.0

    @property
    def variant_text(self) -> str:
        """How the board was found, for people: "background removed, palette iron, upscaled 4x"."""
        parts = [VARIANT_TEXT.get(self.variant, self.variant)] if self.variant else []
        if self.conversion and self.conversion not in ("grey", "luma"):
            parts.append(self.conversion)
        if self.scale > 1:
            parts.append(f"upscaled {self.scale:g}x")
        elif self.scale < 1:
            parts.append(f"detected at {self.scale:.2g}x, refined at full size")
        return ", ".join(parts)

    @property
    def found(self) -> bool:
        return self.status == FOUND

    @property
    def key(self) -> tuple[str, str]:
        return (self.pose, self.camera)

    def object_points(self, board: Board) -> np.ndarray:
        """Board-frame points (N, 3) matching ``corners``."""
        obj = board.object_points()
        return obj if self.ids is None else obj[self.ids]


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


def detection_summary(detections: dict[tuple[str, str], Detection]) -> dict[str, Any]:
    """The detection figures a report carries: per camera the images (not missing), boards found,
    the rate and how many were found by each variant; per image its status, variant, scalar
    conversion, working scale and the reason of a failure. JSON-ready."""
    cams: dict[str, dict[str, Any]] = {}
    views: dict[str, dict[str, Any]] = {}
    for (pose, cam), d in sorted(detections.items()):
        if d.status == MISSING:
            continue
        c = cams.setdefault(cam, {"images": 0, "found": 0, "rate": 0.0, "variants": {}})
        c["images"] += 1
        v: dict[str, Any] = {"status": d.status, "variant": d.variant, "conversion": d.conversion,
                             "scale": round(float(d.scale), 4)}
        if d.found:
            c["found"] += 1
            c["variants"][d.variant or "?"] = c["variants"].get(d.variant or "?", 0) + 1
        else:
            v["reason"] = d.reason
        views[f"{pose}:{cam}"] = v
    for c in cams.values():
        c["rate"] = c["found"] / c["images"] if c["images"] else 0.0
    return {"cameras": cams, "views": views}


def check_image_sizes(session, detections: dict[tuple[str, str], Detection]) -> dict[str, tuple[int, int]]:
    """The image size (w, h) of each camera; raises :class:`InputError` naming the first image
    whose size differs from the camera's other images."""
    sizes: dict[str, tuple[int, int, Path | None]] = {}
    for (pose, cam), d in sorted(detections.items()):
        if d.status == MISSING:
            continue
        if cam not in sizes:
            sizes[cam] = (*d.image_size, d.path)
        elif tuple(sizes[cam][:2]) != tuple(d.image_size):
            w, h, first = sizes[cam]
            raise InputError(
                f"image is {d.image_size[0]}x{d.image_size[1]} but the other images of camera '{cam}' "
                f"are {w}x{h} (e.g. {first}); one camera must always deliver the same size", d.path)
    return {k: (v[0], v[1]) for k, v in sizes.items()}
