"""The point cloud of a registration result: a binary little-endian PLY with every camera's values
(``OUT/pointcloud.ply``, written by :mod:`.export`)."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Iterable

import numpy as np

from ... import __version__
from ..display import display
from ..io.imageio import atomic_path
from ..progress import Reporter, ensure_reporter
from ..registration.hits import values_at
from ..registration.params import RegistrationResult
from .summary import bands as _bands

#: PLY vertex properties that are not camera values.
_PLY_FIXED = ("x", "y", "z", "red", "green", "blue", "row", "col")


def ply_property_names(result: RegistrationResult, cams: list[str] | None = None) -> dict[str, list[str]]:
    """Camera name -> its PLY property names (one per band: ``<cam>`` or ``<cam>_b000``...)."""
    cams = list(result.registered) if cams is None else cams
    used = set(_PLY_FIXED)
    names: dict[str, list[str]] = {}
    for cam in cams:
        base = _ply_name(cam)
        if base in used or base.lower() in used:
            base = f"{base}_value"
        b = _bands(result.registered[cam])
        props = [base] if len(result.registered[cam].shape) == 2 else [f"{base}_b{i:03d}" for i in range(b)]
        props = [p if p not in used else f"{p}_{len(used)}" for p in props]
        used.update(props)
        names[cam] = props
    return names


def write_ply(path: str | Path, result: RegistrationResult, cams: list[str] | None = None,
              colours_rgb8: np.ndarray | None = None, progress: Reporter | None = None) -> int:
    """Write the object-mesh hits as a binary little-endian PLY; returns the number of points.

    Vertex properties: ``x, y, z`` float32 (rig frame, metres); ``red, green, blue`` uchar from
    ``colours_rgb8`` (H, W, 3) (a display rendering); ``row, col`` int32 (the target pixel);
    per camera its registered value(s) as float32 (NaN where that camera is not mapped); per
    source camera ``<cam>_case`` uchar (the case code) and ``<cam>_mixed`` uchar (1 = flagged mixed).
    Points with NaN coordinates are dropped.
    """
    rep = ensure_reporter(progress)
    cams = list(result.registered) if cams is None else cams
    pts = np.asarray(result.points_rig, dtype=np.float32)
    H, W = result.shape
    flat = np.flatnonzero(display.finite_rows(pts.reshape(H * W, 3)))
    rows, cols = np.divmod(flat, W)
    n = rows.size
    names = ply_property_names(result, cams)
    dtype: list[tuple[str, str]] = [("x", "<f4"), ("y", "<f4"), ("z", "<f4"),
                                    ("red", "u1"), ("green", "u1"), ("blue", "u1"),
                                    ("row", "<i4"), ("col", "<i4")]
    for cam in cams:
        dtype += [(p, "<f4") for p in names[cam]]
    used = {d[0] for d in dtype}

    def flag_props(cams_: Iterable[str], suffix: str) -> dict[str, str]:
        """One uint8 property per camera, named ``<cam>_<suffix>`` and made unique."""
        props: dict[str, str] = {}
        for cam in cams_:
            p = f"{_ply_name(cam)}_{suffix}"
            while p in used:
                p += "_"
            used.add(p)
            props[cam] = p
            dtype.append((p, "u1"))
        return props

    case_props = flag_props(result.cases, "case")
    mixed_props = flag_props(getattr(result, "mixed", {}), "mixed")
    dt = np.dtype(dtype)  # packed records, the PLY binary layout
    comment = (f"plantreg {__version__}: object-mesh hits of target '{result.target}' rays, "
               f"rig frame, metres; target image {W}x{H}")
    ply_types = {"<f4": "float", "u1": "uchar", "<i4": "int"}
    header = ["ply", "format binary_little_endian 1.0", f"comment {comment}", f"element vertex {n}"]
    header += [f"property {ply_types[t]} {name}" for name, t in dtype]
    header.append("end_header")
    # records are packed and written in chunks of ~64 MB: a 4K target's hits with 204 bands
    # would otherwise need the whole cloud (and its values) in memory twice
    step = max(1024, (64 << 20) // dt.itemsize)
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as f:
            f.write(("\n".join(header) + "\n").encode("ascii"))
            for a in range(0, n, step):
                rep(0.95 * a / max(n, 1), "point cloud")
                f.write(_ply_records(result, cams, names, case_props, dt, colours_rgb8, pts, flat[a : a + step],
                                     rows[a : a + step], cols[a : a + step], mixed_props).data)
    rep(1.0, "point cloud")
    return n


def _ply_records(result: RegistrationResult, cams: list[str], names: dict[str, list[str]],
                 case_props: dict[str, str], dt: np.dtype, colours_rgb8: np.ndarray | None, pts: np.ndarray,
                 flat: np.ndarray, rows: np.ndarray, cols: np.ndarray,
                 mixed_props: dict[str, str] | None = None) -> np.ndarray:
    """The packed PLY records (m, itemsize) uint8 of the hits at row-major pixel indices ``flat`` (m,)."""
    H, W = result.shape
    m = len(flat)
    raw = np.empty((m, dt.itemsize), dtype=np.uint8)
    v = raw.view(dt).reshape(m)

    def columns(first: str, k: int, typ: str) -> np.ndarray:
        """(m, k) view of ``k`` consecutive properties starting at ``first`` (one copy per camera,
        not one Python-level assignment per band)."""
        off = dt.fields[first][1]
        return np.ndarray((m, k), dtype=typ, buffer=raw, offset=off, strides=(dt.itemsize, np.dtype(typ).itemsize))

    columns("x", 3, "<f4")[:] = pts.reshape(-1, 3)[flat]
    if colours_rgb8 is not None:
        columns("red", 3, "u1")[:] = np.asarray(colours_rgb8).reshape(-1, 3)[flat]
    else:
        columns("red", 3, "u1")[:] = 200
    v["row"], v["col"] = rows, cols
    for cam in cams:
        columns(names[cam][0], len(names[cam]), "<f4")[:] = values_at(result.registered[cam], flat)
    for cam, p in case_props.items():
        v[p] = np.asarray(result.cases[cam], dtype=np.uint8).reshape(-1)[flat]
    for cam, p in (mixed_props or {}).items():
        v[p] = np.asarray(result.mixed[cam], dtype=np.uint8).reshape(-1)[flat]
    return raw


def _ply_name(name: str) -> str:
    """A camera name as a PLY property name (letters, digits, _), not starting with a digit."""
    s = re.sub(r"[^A-Za-z0-9_]", "_", str(name)) or "camera"
    return s if not s[0].isdigit() else f"c{s}"


__all__ = ["ply_property_names", "write_ply"]
