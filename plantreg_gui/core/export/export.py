"""Write a registration result to an output folder (the layout ``plantreg register --out`` promises).

```
OUT/registered/<camera>.tif   float32, target H x W (x bands), NaN where not mapped; tiled, lossless
                              deflate + floating-point predictor (imageio.TIFF_CODECS)
OUT/registered/<camera>.png   display preview (colour map / PCA false colour, contrast stretched)
OUT/cases/<camera>.png        uint8 case code per target pixel, every source camera
OUT/cases/<camera>_edge.png   uint8 255 = P1 pixel flagged mixed (footprint across a silhouette), else 0
OUT/flying.png                uint8 255 = depth pixel detected as flying (depth camera's grid), else 0
OUT/areas.png                 uint8 area code per target pixel (4 = P4, 5 = P5, 6 = P6)
OUT/pointcloud.ply            object-mesh hits (rig frame) with every camera's values + RGB colour
OUT/mosaic.png                tiles alternating the modalities' previews
OUT/summary.json              inputs, versions, parameters, case counts, timings
```

The folder is built under a temporary name beside ``OUT`` and moved into place at the end
(:func:`~plantreg_gui.core.io.imageio.atomic_output_dir`), so a failed or cancelled export never
leaves a complete-looking folder behind.

Length: the output registry and one writer per part (TIFF tiles, PNG masks, PLY, summary) with
the background encoding they share.
"""

from __future__ import annotations

import datetime as _dt
import functools
import json
import platform
import re
import time
from pathlib import Path
from dataclasses import dataclass, field
from typing import Any, Callable, Iterable, Mapping

import numpy as np

from ... import __version__
from ...versions import dist_version as _dist_version
from ..display import display
from ..camera import modality
from ..errors import InputError
from ..io.imageio import (TIFF_CODEC_DEFAULT, atomic_output_dir, atomic_path, atomic_write_text,
                      dense_tiles, tiff_tile_edge, write_png, write_tiff_tiled)
from ..progress import Reporter, ensure_reporter
from ..data.recording import Recording
from ..registration.hits import HitImage, values_at
from ..registration.cases import AREA_NAMES, CASE_NAMES
from ..registration.params import RegistrationResult
from ..camera.rig import Rig

SUMMARY_FORMAT = "plantreg.summary"
SUMMARY_VERSION = 2  # 2: "tof" (flying pixels, mixed-pixel flags), parameters of the depth clean-up

# ---------------------------------------------------------------------- the output parts (one registry)
@dataclass
class ExportContext:
    """What every part's writer gets: the temporary output ``folder``, the result, its ``cams``
    (target first), ``preview(cam)`` (the display rendering, computed once), the options, and
    the bookkeeping the summary reports (``written`` relative paths, ``timings``)."""

    folder: Path
    result: RegistrationResult
    rig: Rig
    recording: Recording | None
    cams: list[str]
    preview: Callable[[str], np.ndarray]
    tiff_codec: str
    mosaic_tile: int | None
    inputs: dict[str, Any] | None
    t_start: float
    written: list[str] = field(default_factory=list)
    timings: dict[str, float] = field(default_factory=dict)
    background: Any = None  # _Background: files encoded in a thread while the others are made
    early: Any = None  # EarlyTiffs: registered TIFFs already being encoded during the registration
    summary_draft: dict[str, Any] | None = None  # summary.json but its timings (_summary_draft)


@dataclass(frozen=True)
class OutputPart:
    """One selectable part of the output. ``steps(result, cams)`` -> ``[("kind[:camera]", weight)]``
    (weights: rough relative cost, so the progress bar moves evenly); ``write(ctx, kind, camera,
    progress)`` writes one step into ``ctx.folder`` and returns its relative path. ``label`` is
    what the GUI's export dialog says; ``cli`` the name ``--outputs`` lists (default ``key``)."""

    key: str
    label: str
    steps: Callable[[RegistrationResult, list[str]], list[tuple[str, float]]]
    write: Callable[[ExportContext, str, str, Reporter], str]
    cli: str = ""


def _write_registered(ctx: ExportContext, kind: str, cam: str, rep: Reporter) -> str:
    # encoded in a background thread while the previews, the point cloud and the rest are made
    # here (the codecs release the GIL); waited for before the summary (_wait_background)
    rel = f"registered/{_safe(cam)}.tif"
    ctx.timings.setdefault(kind, 0.0)
    if ctx.early is not None and ctx.early.has(cam, ctx.result.registered[cam], ctx.tiff_codec):
        ctx.background.submit(ctx.early.take, cam, ctx.folder / rel)  # waits for it, moves it in
    else:
        ctx.background.submit(_write_registered_tiff, ctx.folder / rel, ctx.result.registered[cam], ctx.tiff_codec)
    return rel


def _wait_background(ctx: ExportContext, rep: Reporter, fraction: float) -> None:
    """Wait for the files written in the background (their errors are raised here)."""
    if ctx.background is not None and ctx.background.pending():
        rep(fraction, "writing registered images")
        ctx.timings["registered"] = ctx.timings.get("registered", 0.0) + ctx.background.wait()


def _write_preview(ctx: ExportContext, kind: str, cam: str, rep: Reporter) -> str:
    rel = f"registered/{_safe(cam)}.png"
    write_png(ctx.folder / rel, ctx.preview(cam))
    return rel


def _write_cases(ctx: ExportContext, kind: str, cam: str, rep: Reporter) -> str:
    rel = f"cases/{_safe(cam)}.png"
    write_png(ctx.folder / rel, np.asarray(ctx.result.cases[cam], dtype=np.uint8))
    return rel


def _write_areas(ctx: ExportContext, kind: str, cam: str, rep: Reporter) -> str:
    write_png(ctx.folder / "areas.png", np.asarray(ctx.result.area, dtype=np.uint8))
    return "areas.png"


def _write_pointcloud(ctx: ExportContext, kind: str, cam: str, rep: Reporter) -> str:
    colour_cam = _colour_camera(ctx.result, ctx.rig)
    write_ply(ctx.folder / "pointcloud.ply", ctx.result, ctx.cams,
              None if colour_cam is None else ctx.preview(colour_cam), rep)
    return "pointcloud.ply"


def _write_mosaic(ctx: ExportContext, kind: str, cam: str, rep: Reporter) -> str:
    tile = ctx.mosaic_tile or display.default_tile(ctx.result.shape)
    write_png(ctx.folder / "mosaic.png", display.mosaic([ctx.preview(c) for c in ctx.cams], tile))
    return "mosaic.png"


def _summary_draft(ctx: ExportContext) -> dict[str, Any]:
    """``summary.json`` but its export timings: made while the registered images are still being
    encoded in the background (case counts, mapped pixels: off the end of an export)."""
    return build_summary(ctx.result, ctx.rig, ctx.recording, ctx.inputs, export_timings={},
                         files=ctx.written + ["summary.json"])


def _write_summary(ctx: ExportContext, kind: str, cam: str, rep: Reporter) -> str:
    summary = ctx.summary_draft if ctx.summary_draft is not None else _summary_draft(ctx)
    ctx.timings["total"] = time.perf_counter() - ctx.t_start
    summary["export_timings"] = _jsonable(dict(ctx.timings))
    atomic_write_text(ctx.folder / "summary.json", json.dumps(summary, indent=2, allow_nan=False) + "\n")
    return "summary.json"


def _write_mask(ctx: ExportContext, kind: str, cam: str, rep: Reporter) -> str:
    """``cases/<cam>_edge.png`` (kind ``edges``) or ``flying.png``; returns the relative path.
    Masks are uint8, 255 = flagged, so any viewer shows them."""
    if kind == "edges":
        rel = f"cases/{_safe(cam)}_edge.png"
        mask = np.asarray(ctx.result.mixed[cam], dtype=bool)
    else:
        rel = "flying.png"
        mask = np.asarray(ctx.result.flying, dtype=bool)
    write_png(ctx.folder / rel, mask.view(np.uint8) * np.uint8(255))  # 0 / 255 (no int64 intermediate)
    return rel


#: The parts of the output, in writing order: the one place an output is declared. The command
#: line's ``--outputs``, the GUI's export dialog and the progress weights all read it; adding an
#: output = one :class:`OutputPart` here (the summary stays last: it lists the files written).
OUTPUT_PARTS: tuple[OutputPart, ...] = (
    OutputPart("registered", "Registered images (float32 TIFF, NaN = not mapped)",
               lambda r, cams: [(f"registered:{c}", 1.0 + 0.02 * _bands(r.registered[c])) for c in cams],
               _write_registered),
    OutputPart("previews", "Display previews (PNG, as shown here)",
               lambda r, cams: [(f"previews:{c}", 1.0 + 0.01 * _bands(r.registered[c])) for c in cams],
               _write_preview),
    OutputPart("cases", "Case masks per source (PNG, codes 0-6)",
               lambda r, cams: [(f"cases:{c}", 0.3) for c in r.cases], _write_cases),
    OutputPart("edges", "Mixed edge pixels per source (PNG mask)",
               lambda r, cams: [(f"edges:{c}", 0.3) for c in r.mixed], _write_mask),
    OutputPart("flying", "Flying depth pixels (PNG mask, the depth camera's grid)",
               lambda r, cams: [("flying", 0.2)] if r.flying is not None else [], _write_mask),
    OutputPart("areas", "Area mask of the target (PNG, codes 4-6)", lambda r, cams: [("areas", 0.3)], _write_areas),
    OutputPart("pointcloud", "Point cloud with every modality's values (PLY)",
               lambda r, cams: [("pointcloud", 2.0 + 0.05 * sum(_bands(r.registered[c]) for c in cams))],
               _write_pointcloud, cli="ply"),
    # a recording with a depth map only has nothing to tile
    OutputPart("mosaic", "Mosaic of all modalities (PNG)", lambda r, cams: [("mosaic", 1.0)] if cams else [],
               _write_mosaic),
    OutputPart("summary", "Summary: inputs, parameters, case counts, timings (JSON)",
               lambda r, cams: [("summary", 0.0)], _write_summary),
)

#: Selectable parts of the output (``what``), in writing order (from :data:`OUTPUT_PARTS`).
OUTPUTS = tuple(p.key for p in OUTPUT_PARTS)

def output_choices() -> str:
    """The part names the command line's ``--outputs`` takes, comma-separated."""
    return ",".join(p.cli or p.key for p in OUTPUT_PARTS)


def _keys() -> tuple[str, ...]:
    return tuple(p.key for p in OUTPUT_PARTS)  # read at call time: the registry is the truth


def _alias(word: str) -> str:
    return next((p.key for p in OUTPUT_PARTS if word == p.cli), word)


def parse_outputs(text: str | Iterable[str] | None) -> tuple[str, ...]:
    """``"registered,cases,ply"`` (or a list) -> the :data:`OUTPUT_PARTS` keys, in registry order;
    None or ``"all"`` -> all. Unknown names raise :class:`InputError`."""
    keys = _keys()
    if text is None:
        return keys
    words = [w.strip() for w in (text.split(",") if isinstance(text, str) else text) if w.strip()]
    if words == ["all"]:
        return keys
    parts = {_alias(w) for w in words}
    unknown = sorted(w for w in words if _alias(w) not in keys)
    if unknown or not parts:
        raise InputError(f"--outputs: unknown part(s) {', '.join(unknown) or '(none given)'}; "
                         f"choose from {output_choices()} or all")
    return tuple(o for o in keys if o in parts)


#: PLY vertex properties that are not camera values.
_PLY_FIXED = ("x", "y", "z", "red", "green", "blue", "row", "col")


def write_outputs(
    result: RegistrationResult,
    rig: Rig,
    recording: Recording | None,
    out: str | Path,
    overwrite: bool = False,
    progress: Reporter | None = None,
    inputs: dict[str, Any] | None = None,
    what: Iterable[str] | None = None,
    display_options: Mapping[str, Mapping[str, Any]] | None = None,
    tiff_codec: str = TIFF_CODEC_DEFAULT,
    mosaic_tile: int | None = None,
    early: "EarlyTiffs | None" = None,
) -> Path:
    """Write ``result`` into the folder ``out`` (layout in the module docstring); returns ``out``.

    ``inputs`` adds to the provenance recorded in ``summary.json`` (e.g. ``{"rig": path}``; the
    recording's own paths are added automatically). ``what`` selects a subset of
    :data:`OUTPUTS` (default: all). ``display_options`` maps a camera name to keyword
    arguments of :func:`display.to_rgb8` (cmap, limits, percentiles, bands) for the previews,
    the mosaic and the point-cloud colours, so an export looks like the GUI's view.
    ``tiff_codec``: the registered TIFFs' lossless compression (:data:`~.imageio.TIFF_CODECS`).
    ``mosaic_tile`` the mosaic's tile size in pixels (default :func:`display.default_tile`; the
    workspace passes its screen's tile). ``early``: registered TIFFs whose encoding started during
    the registration (:class:`EarlyTiffs`); those are moved in instead of encoded again.

    Raises :class:`InputError` if ``out`` exists and is not empty and ``overwrite`` is False;
    :class:`~plantreg_gui.core.errors.Cancelled` if cancelled through ``progress`` (nothing is
    left at ``out`` then).
    """
    rep = ensure_reporter(progress)
    sel = set(_keys()) if what is None else {_alias(w) for w in what}
    unknown = sel - set(_keys())
    if unknown:
        raise ValueError(f"unknown output parts {sorted(unknown)}; choose from {_keys()}")
    out = Path(out)
    t_start = time.perf_counter()
    cams = _camera_order(result, rig)
    _check_file_names(list(dict.fromkeys([*cams, *result.cases])))
    opts = {k: dict(v) for k, v in (display_options or {}).items()}
    previews: dict[str, np.ndarray] = {}

    def preview(cam: str) -> np.ndarray:
        if cam not in previews:
            previews[cam] = display.to_rgb8(result.registered[cam], modality=_modality(rig, cam),
                                            **opts.get(cam, {}))
        return previews[cam]

    # (part, step, weight) in OUTPUT_PARTS order; the weights make the progress bar move evenly
    steps = [(part, step, w) for part in OUTPUT_PARTS if part.key in sel for step, w in part.steps(result, cams)]
    total = sum(w for _, _, w in steps) or 1.0

    keep: list[Path] = [Path(v) for k, v in (inputs or {}).items()
                        if isinstance(v, Path) or (k == "rig" and isinstance(v, str))]
    if recording is not None and recording.folder is not None:
        keep += [Path(recording.folder), *map(Path, recording.paths.values())]
    check_output_spares_inputs(out, keep)
    with atomic_output_dir(out, overwrite) as tmp, _Background() as background:
        ctx = ExportContext(tmp, result, rig, recording, cams, preview, tiff_codec, mosaic_tile, inputs, t_start,
                            background=background, early=early)
        done = 0.0
        for part, step, weight in steps:
            kind, _, cam = step.partition(":")
            if part.key == "summary":  # it lists the timings and files: the background's first
                ctx.summary_draft = _summary_draft(ctx)  # the rest of it while the background runs
                _wait_background(ctx, rep, done / total)
            rep(done / total, f"writing {_step_label(kind, cam)}")
            t0 = time.perf_counter()
            rel = part.write(ctx, kind, cam, rep.sub(done / total, (done + weight) / total))
            if kind != "summary":  # the summary holds the timings: it is written last, untimed
                ctx.timings[kind] = ctx.timings.get(kind, 0.0) + time.perf_counter() - t0
            ctx.written.append(rel)
            done += weight
        _wait_background(ctx, rep, done / total)
        rep.check()  # a cancel during the last file still leaves nothing behind
    if not rep.cancel.cancelled:  # the folder is complete now: a late cancel changes nothing
        rep(1.0, f"wrote {out}")
    return out


def _write_registered_tiff(path: Path, reg: Any, codec: str, stop: Any = None) -> float:
    """One ``registered/<camera>.tif`` (tiled, compressed, empty tiles encoded once); seconds taken.
    ``stop`` (a threading.Event): set, the writing ends with :class:`~.errors.Cancelled` (no file)."""
    t0 = time.perf_counter()
    if isinstance(reg, HitImage):  # expanded tile by tile, never as a whole
        shape, tile_of = reg.shape, _hit_tiles(reg)
    else:
        reg = np.asarray(reg, dtype=np.float32)
        shape, tile_of = reg.shape, dense_tiles(reg)
    if stop is not None:
        inner = tile_of

        def tile_of(r0: int, r1: int, c0: int, c1: int):  # noqa: F811 - the same with a stop check
            if stop.is_set():
                from ..errors import Cancelled

                raise Cancelled("stopped")
            return inner(r0, r1, c0, c1)
    write_tiff_tiled(path, shape, np.float32, tile_of, codec=codec)
    return time.perf_counter() - t0


class EarlyTiffs:
    """``registered/<camera>.tif`` files encoded in a background thread while the registration
    still runs, as a context: pass it as ``on_image`` to :meth:`~.register.Registrar.register`
    and as ``early`` to :func:`write_outputs`, which moves the files into its folder.

    Why: registering into a 4K view keeps one core busy for seconds while the other idles, and
    then the export is bound by deflating the 204-band cube's ~0.8 GB of hit values on both
    cores; sources are registered cube first (``register``), so its TIFF is encoded while the
    other sources are registered. The files are the ones :func:`write_outputs` would write (the
    same function, from the same arrays, which must not change in between). They are staged in a
    hidden ``.<out>.XXXX.part`` folder beside ``out``; leaving the context (also by an error)
    stops the encoding and removes that folder.
    """

    def __init__(self, out: str | Path, codec: str = TIFF_CODEC_DEFAULT):
        self.out, self.codec = Path(out), codec
        self._jobs: dict[str, tuple[Any, Any, Path]] = {}  # camera -> (image, future, staged path)

    def __enter__(self) -> "EarlyTiffs":
        import tempfile
        import threading
        from concurrent.futures import ThreadPoolExecutor

        from .. import signals

        self.out.parent.mkdir(parents=True, exist_ok=True)
        with signals.deferred():  # a signal here would leave the folder without __exit__ to remove it
            self._dir = Path(tempfile.mkdtemp(prefix=f".{self.out.name}.", suffix=".part", dir=self.out.parent))
            self._stop = threading.Event()
            self._pool = ThreadPoolExecutor(1, thread_name_prefix="plantreg-early")
        return self

    def __call__(self, cam: str, image: Any) -> None:
        path = self._dir / f"{_safe(cam)}.tif"
        if cam not in self._jobs:
            self._jobs[cam] = (image, self._pool.submit(_write_registered_tiff, path, image, self.codec, self._stop),
                               path)

    def has(self, cam: str, image: Any, codec: str) -> bool:
        """Whether ``cam``'s TIFF of this very ``image`` in ``codec`` is (being) encoded here."""
        return cam in self._jobs and self._jobs[cam][0] is image and codec == self.codec

    def take(self, cam: str, dest: Path) -> float:
        """Wait for ``cam``'s TIFF (its error is raised here) and move it to ``dest``; seconds encoding took."""
        import os

        from ..io.imageio import _renamed

        _image, fut, path = self._jobs.pop(cam)
        try:
            seconds = fut.result()
        except OSError as e:  # named as the file the user gets (write_outputs names it under OUT)
            raise _renamed(e, path, dest) from None
        dest.parent.mkdir(parents=True, exist_ok=True)
        os.replace(path, dest)
        return seconds

    def __exit__(self, *exc) -> None:
        import shutil

        self._stop.set()
        self._pool.shutdown(wait=True, cancel_futures=True)
        shutil.rmtree(self._dir, ignore_errors=True)


def _hit_tiles(reg: HitImage) -> Callable[[int, int, int, int], np.ndarray | None]:
    """``tile_of`` for :func:`~.imageio.write_tiff_tiled` of a HitImage: its blocks, and None at
    once for a block without a hit, from an occupancy grid of the writer's tile size made once.
    Why: ~90 % of a 4K view's 32,400 tiles hold no hit, and finding that out by searching the
    hits tile by tile (``HitImage.block``) holds the GIL for long; the grid is quick.
    Any block geometry is answered correctly (every grid cell it touches is looked at)."""
    H, W = reg.shape[:2]
    g = tiff_tile_edge(_bands(reg), 4)  # the writer's tile edge for float32: one cell per tile
    rows, cols = np.divmod(np.asarray(reg.index), W)
    occupied = np.zeros((-(-H // g), -(-W // g)), bool)
    occupied[rows // g, cols // g] = True

    def tile_of(r0: int, r1: int, c0: int, c1: int) -> np.ndarray | None:
        if not occupied[r0 // g : (r1 - 1) // g + 1, c0 // g : (c1 - 1) // g + 1].any():
            return None
        return reg.block(r0, r1, c0, c1)
    return tile_of


class _Background:
    """One background thread for output files, as a context: leaving it (also by an exception
    or a cancel) cancels what has not started and waits for what runs, so that no file is
    written into a folder that is being removed."""

    def __enter__(self) -> "_Background":
        from concurrent.futures import ThreadPoolExecutor

        self._pool = ThreadPoolExecutor(1, thread_name_prefix="plantreg-write")
        self._futures: list = []
        return self

    def submit(self, fn, *args) -> None:
        self._futures.append(self._pool.submit(fn, *args))

    def pending(self) -> bool:
        return bool(self._futures)

    def wait(self) -> float:
        """Wait for every submitted call (in order; the first error is raised); sum of their results."""
        futures, self._futures = self._futures, []
        return float(sum(f.result() for f in futures))

    def __exit__(self, *exc) -> None:
        self._pool.shutdown(wait=True, cancel_futures=True)


def check_output_spares_inputs(out: str | Path, inputs: Iterable[str | Path]) -> None:
    """Raise :class:`InputError` if the output folder ``out`` is, or contains, one of ``inputs``
    (files or folders): replacing it (``overwrite``) would delete the user's recording or rig."""
    out_r = Path(out).resolve()
    for p in inputs:
        p_r = Path(p).resolve()
        if p_r == out_r or out_r in p_r.parents:
            raise InputError(f"the output folder would replace an input ({p}); choose an output folder "
                             "outside the recording and the rig file's folder", out)


# ---------------------------------------------------------------------- mixed-pixel and flying-pixel masks
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


# ---------------------------------------------------------------------- registered images
# ---------------------------------------------------------------------- point cloud
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


# ---------------------------------------------------------------------- summary
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
    for cam in _camera_order(result, rig):
        reg = result.registered[cam]
        if isinstance(reg, HitImage):  # NaN off the hits by construction
            n_mapped = int(np.count_nonzero(display.finite_rows(reg.values)))
        else:
            reg = np.asarray(reg)
            n_mapped = int(np.count_nonzero(display.finite_rows(reg.reshape(reg.shape[0] * reg.shape[1], -1))))
        c = _rig_camera(rig, cam)
        cameras[cam] = {
            "modality": c.modality if c is not None else None,
            "size": [c.width, c.height] if c is not None else None,
            "bands": _bands(reg),
            "mapped_pixels": n_mapped,
            "role": "target" if cam == result.target else "source",
        }
    n_points = int(np.count_nonzero(display.finite_rows(np.asarray(result.points_rig).reshape(-1, 3))))
    return _jsonable({
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


def _jsonable(x: Any) -> Any:
    """numpy scalars/arrays, Paths and tuples -> JSON types; NaN/inf -> None."""
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return _jsonable(x.tolist())
    if isinstance(x, np.generic):
        return _jsonable(x.item())
    if isinstance(x, float):
        return x if np.isfinite(x) else None
    if isinstance(x, Path):
        return str(x)
    if x is None or isinstance(x, (str, int, bool)):
        return x
    return str(x)


# ---------------------------------------------------------------------- helpers
def _safe(name: str) -> str:
    """A camera name usable as a file name and PLY property (letters, digits, _ - .)."""
    s = re.sub(r"[^A-Za-z0-9_.-]", "_", str(name))
    return s or "camera"


def _check_file_names(cams: list[str]) -> None:
    """Two cameras whose names make the same file name would overwrite each other's outputs."""
    seen: dict[str, str] = {}
    for cam in cams:
        other = seen.setdefault(_safe(cam).lower(), cam)  # .lower(): case-insensitive file systems
        if other != cam:
            raise InputError(f"cameras '{other}' and '{cam}' would be written to the same files "
                             f"('{_safe(cam)}.*'); rename one of them in the rig")


def _ply_name(name: str) -> str:
    """A camera name as a PLY property name (letters, digits, _), not starting with a digit."""
    s = re.sub(r"[^A-Za-z0-9_]", "_", str(name)) or "camera"
    return s if not s[0].isdigit() else f"c{s}"


def _bands(a: np.ndarray) -> int:
    shape = a.shape if hasattr(a, "shape") else np.shape(a)  # a HitImage is not expanded for this
    return int(shape[2]) if len(shape) == 3 else 1


def _rig_camera(rig: Rig, name: str):
    for c in rig.cameras:
        if c.name == name:
            return c
    return None


def _modality(rig: Rig, name: str) -> str | None:
    c = _rig_camera(rig, name)
    return c.modality if c is not None else None


def _camera_order(result: RegistrationResult, rig: Rig) -> list[str]:
    """Target first, then the sources in rig order (cameras unknown to the rig last)."""
    order = [result.target] if result.target in result.registered else []
    order += [c for c in rig.names if c in result.registered and c not in order]
    order += [c for c in result.registered if c not in order]
    return order


def _colour_camera(result: RegistrationResult, rig: Rig) -> str | None:
    """The camera whose display rendering colours the point cloud: the rgb camera, else the target
    (None when no camera has an image)."""
    for c in rig.cameras:
        if modality.is_colour(c.modality) and c.name in result.registered:
            return c.name
    if result.target in result.registered:
        return result.target
    return next(iter(result.registered), None)


def _step_label(kind: str, cam: str) -> str:
    return {"registered": f"registered/{cam}.tif", "previews": f"registered/{cam}.png",
            "cases": f"cases/{cam}.png", "edges": f"cases/{cam}_edge.png"}.get(
        kind, {"areas": "areas.png", "pointcloud": "pointcloud.ply", "flying": "flying.png",
               "mosaic": "mosaic.png", "summary": "summary.json"}.get(kind, kind))


__all__ = ["EarlyTiffs", "OUTPUTS", "OUTPUT_PARTS", "OutputPart", "parse_outputs", "write_outputs", "write_ply", "build_summary",
           "ply_property_names"]
