"""Intrinsics given for a camera instead of calibrated: ``--intrinsics CAM=RIG.json`` or
``"intrinsics": "RIG.json"`` in the camera's entry of ``session.json`` (relative to the session).

The camera of that name in the rig file (or its only camera) gives K and distortion; when the
file carries standard errors (a plantreg calibration's provenance,
``calibration.cameras.CAM.uncertainty.std``) they are priors, otherwise the intrinsics are held
fixed and only the camera's pose is estimated (:func:`.calibrate.calibrate`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..camera.rig import Rig
from .bundle import param_names
from .session import Session


@dataclass
class KnownIntrinsics:
    """Intrinsics given for a camera (calibrated on its own, or the maker's): ``K`` (3, 3),
    ``dist`` (5,) or (8,), ``std`` parameter name -> standard error (empty: held fixed; else used
    as priors), ``source`` where they came from (a file name)."""

    K: np.ndarray
    dist: np.ndarray
    std: dict[str, float] = field(default_factory=dict)
    source: str = ""


def load_known_intrinsics(path: str | Path, camera: str, what: str = "--intrinsics") -> KnownIntrinsics:
    """The intrinsics of ``camera`` from a rig file (the camera of that name, or its only camera),
    with their standard errors when the file carries them (a plantreg calibration's provenance).
    Raises :class:`InputError` naming the file."""
    path = Path(path)
    rig = Rig.load(path)
    names = [c.name for c in rig.cameras]
    if camera in names:
        cam = rig.camera(camera)
    elif len(names) == 1:
        cam = rig.cameras[0]
    else:
        raise InputError(f"{what}: the rig file has no camera '{camera}' (it has {', '.join(names)})", path)
    std = {}
    prov = rig.extra.get("calibration", {}) if isinstance(rig.extra.get("calibration"), dict) else {}
    u = prov.get("cameras", {}).get(cam.name, {}).get("uncertainty", {}) if isinstance(prov.get("cameras"), dict) else {}
    for k, v in (u.get("std", {}) if isinstance(u, dict) else {}).items():
        if k in param_names(len(cam.dist)) and isinstance(v, (int, float)) and np.isfinite(v) and v > 0:
            std[k] = float(v)
    ki = KnownIntrinsics(np.asarray(cam.K, float), np.asarray(cam.dist, float).ravel().copy(), std, str(path))
    ki.width, ki.height = cam.width, cam.height  # type: ignore[attr-defined]
    return ki


def check_known_intrinsics(session: Session, known: dict[str, KnownIntrinsics],
                           sizes: dict[str, tuple[int, int]] | None = None) -> None:
    """Every given camera exists in the session and (with ``sizes``, or from its first image)
    has the size the intrinsics were calibrated for."""
    from ..io.imageio import read_image

    for cam, k in known.items():
        if cam not in session.cameras:
            raise InputError(f"--intrinsics {cam}=...: the session has no camera '{cam}' "
                             f"({', '.join(session.cameras)})", k.source or None)
        w, h = getattr(k, "width", None), getattr(k, "height", None)
        if w is None:
            continue
        if sizes and cam in sizes:
            size = sizes[cam]
        else:
            first = next((p.images[cam] for p in session.poses if cam in p.images), None)
            if first is None:
                continue
            shape = read_image(first).shape
            size = (shape[1], shape[0])
        if tuple(size) != (w, h):
            raise InputError(f"the intrinsics of camera '{cam}' are for {w}x{h} images, but the session's are "
                             f"{size[0]}x{size[1]}", k.source or None)


def session_known_intrinsics(session: Session) -> dict[str, KnownIntrinsics]:
    """``"intrinsics": "RIG.json"`` of cameras in ``session.json`` (paths relative to the session)."""
    out = {}
    for cam, meta in (getattr(session, "camera_meta", {}) or {}).items():
        f = meta.get("intrinsics")
        if cam in session.cameras and f:
            fp = Path(f) if Path(f).is_absolute() else Path(session.folder) / f
            out[cam] = load_known_intrinsics(fp, cam, f"session.json camera '{cam}' intrinsics")
    return out


