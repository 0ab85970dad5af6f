"""``summary.json`` of a registration result: inputs, versions, parameters, case counts, timings
(``OUT/summary.json``, written by :mod:`.export`), and the helpers it shares with the other parts."""

from __future__ import annotations

import datetime as _dt
import functools
import platform
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from ... import __version__
from ...versions import dist_version as _dist_version
from ..camera.rig import Rig
from ..data.recording import Recording
from ..display import display
from ..registration.cases import AREA_NAMES, CASE_NAMES
from ..registration.hits import HitImage
from ..registration.params import RegistrationResult

SUMMARY_FORMAT = "plantreg.summary"


SUMMARY_VERSION = 2  # 2: "tof" (flying pixels, mixed-pixel flags), parameters of the depth clean-up


def tof_summary(result: RegistrationResult) -> dict[str, Any]:
    """The ``tof`` block of ``summary.json``: flying-pixel count, per-source mixed-pixel counts."""
    fly = result.flying
    n_depth = int(np.asarray(fly).size) if fly is not None else 0
    n_fly = int(np.count_nonzero(fly)) if fly is not None else 0
    mixed = {}
    for cam, m in result.mixed.items():
        n_p1 = int(np.count_nonzero(np.asarray(result.cases[cam]) == 1)) if cam in result.cases else 0
        n_m = int(np.count_nonzero(m))
        mixed[cam] = {"pixels": n_m, "percent_of_p1": round(100.0 * n_m / n_p1, 3) if n_p1 else 0.0}
        if cam in result.stats.get("mixed_radius_px", {}):
            mixed[cam]["radius_px"] = result.stats["mixed_radius_px"][cam]
    return {"flying_pixels": n_fly, "flying_percent_of_depth": round(100.0 * n_fly / n_depth, 4) if n_depth else 0.0,
            "filled_pixels": int(result.stats.get("filled_pixels", 0)),
            "flying_handling": ("repaired" if getattr(result.params, "flying_repair", True) else "removed")
            if getattr(result.params, "flying_filter", False) else "off",
            "mixed": mixed}


def build_summary(result: RegistrationResult, rig: Rig, recording: Recording | None,
                  inputs: Mapping[str, Any] | None = None, export_timings: Mapping[str, float] | None = None,
                  files: list[str] | None = None) -> dict[str, Any]:
    """The content of ``summary.json`` (JSON-ready dict)."""
    H, W = result.shape
    n = H * W
    inp: dict[str, Any] = {}
    if recording is not None and recording.folder is not None:
        inp["recording"] = str(Path(recording.folder).resolve())
        inp["images"] = {k: str(Path(p).resolve()) for k, p in recording.paths.items() if k != "depth"}
        if "depth" in recording.paths:
            inp["depth"] = str(Path(recording.paths["depth"]).resolve())
    for k, val in (inputs or {}).items():
        inp[k] = str(Path(val).resolve()) if isinstance(val, Path) else val
    cases = {}
    for cam, codes in result.cases.items():
        counts = np.bincount(np.asarray(codes, dtype=np.uint8).ravel(), minlength=256)
        cases[cam] = {CASE_NAMES[c]: {"code": c, "pixels": int(counts[c]), "percent": round(100.0 * counts[c] / n, 3)}
                      for c in sorted(CASE_NAMES)}
    acounts = np.bincount(np.asarray(result.area, dtype=np.uint8).ravel(), minlength=256)
    areas = {AREA_NAMES[c]: {"code": c, "pixels": int(acounts[c]), "percent": round(100.0 * acounts[c] / n, 3)}
             for c in sorted(AREA_NAMES)}
    cameras = {}
    for cam in camera_order(result, rig):
        reg = result.registered[cam]
        if isinstance(reg, HitImage):  # NaN off the hits by construction
            n_mapped = int(np.count_nonzero(display.finite_rows(reg.values)))
        else:
            reg = np.asarray(reg)
            n_mapped = int(np.count_nonzero(display.finite_rows(reg.reshape(reg.shape[0] * reg.shape[1], -1))))
        c = rig_camera(rig, cam)
        cameras[cam] = {
            "modality": c.modality if c is not None else None,
            "size": [c.width, c.height] if c is not None else None,
            "bands": bands(reg),
            "mapped_pixels": n_mapped,
            "role": "target" if cam == result.target else "source",
        }
    n_points = int(np.count_nonzero(display.finite_rows(np.asarray(result.points_rig).reshape(-1, 3))))
    return jsonable({
        "format": SUMMARY_FORMAT,
        "version": SUMMARY_VERSION,
        "date": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        "target": result.target,
        "target_size": [W, H],
        "inputs": inp,
        "versions": _versions(),
        "parameters": result.params.to_dict(),
        "rig": {"depth_camera": rig.depth_camera, "depth_scale": rig.depth_scale,
                "roi": {"min": rig.roi_min.tolist(), "max": rig.roi_max.tolist()}},
        "cameras": cameras,
        "cases": cases,
        "areas": areas,
        "points": n_points,
        "timings": dict(result.timings),
        "warnings": list(getattr(result, "warnings", [])),
        "export_timings": dict(export_timings or {}),
        "stats": dict(result.stats),
        "tof": tof_summary(result),
        "case_codes": {str(k): v for k, v in CASE_NAMES.items()},
        "area_codes": {str(k): v for k, v in AREA_NAMES.items()},
        "files": list(files or []),
    })


def _versions() -> dict[str, str | None]:
    return dict(_versions_cached())


@functools.lru_cache(maxsize=1)
def _versions_cached() -> dict[str, str | None]:
    """Looked up once per process (a batch worker asks per recording)."""
    import cv2

    v: dict[str, str | None] = {"plantreg": __version__, "python": platform.python_version(),
                                "numpy": np.__version__, "opencv": cv2.__version__}
    for mod in ("open3d", "tifffile", "plyfile"):
        v[mod] = _dist_version(mod)
    return v


def jsonable(x: Any) -> Any:
    """numpy scalars/arrays, Paths and tuples -> JSON types; NaN/inf -> None."""
    if isinstance(x, dict):
        return {str(k): jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return jsonable(x.tolist())
    if isinstance(x, np.generic):
        return jsonable(x.item())
    if isinstance(x, float):
        return x if np.isfinite(x) else None
    if isinstance(x, Path):
        return str(x)
    if x is None or isinstance(x, (str, int, bool)):
        return x
    return str(x)


def bands(a: np.ndarray) -> int:
    shape = a.shape if hasattr(a, "shape") else np.shape(a)  # a HitImage is not expanded for this
    return int(shape[2]) if len(shape) == 3 else 1


def rig_camera(rig: Rig, name: str):
    for c in rig.cameras:
        if c.name == name:
            return c
    return None


def camera_order(result: RegistrationResult, rig: Rig) -> list[str]:
    """Target first, then the sources in rig order (cameras unknown to the rig last)."""
    order = [result.target] if result.target in result.registered else []
    order += [c for c in rig.names if c in result.registered and c not in order]
    order += [c for c in result.registered if c not in order]
    return order


__all__ = ["SUMMARY_FORMAT", "SUMMARY_VERSION", "build_summary", "tof_summary"]
