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

The point cloud is written by :mod:`.ply`, ``summary.json``'s content made by :mod:`.summary`.
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from dataclasses import dataclass, field
from typing import Any, Callable, Iterable, Mapping

import numpy as np

from ..camera import modality
from ..camera.rig import Rig
from ..data.recording import Recording
from ..display import display
from ..errors import InputError
from ..io.imageio import TIFF_CODEC_DEFAULT, atomic_output_dir, atomic_write_text, write_png
from ..io.lock import claim_output
from ..progress import Reporter, ensure_reporter
from ..registration.params import RegistrationResult
from ..validate import file_stem
from .ply import ply_property_names, write_ply
from .summary import (SUMMARY_FORMAT, SUMMARY_VERSION, bands as _bands, build_summary, camera_order as _camera_order,
                      jsonable, rig_camera, tof_summary)
from .tiffs import Background, EarlyTiffs, write_registered_tiff


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
    background: Any = None  # Background: files encoded in a thread while the others are made
    early: Any = None  # EarlyTiffs: registered TIFFs already being encoded during the registration
    summary_draft: dict[str, Any] | None = None  # summary.json but its timings (_summary_draft)


@dataclass(frozen=True)
class OutputPart:
    """One selectable part of the output. ``steps(result, cams)`` -> ``[("kind[:camera]", weight)]``
    (weights: rough relative cost, so the progress bar moves evenly); ``write(ctx, kind, camera,
    progress)`` writes one step into ``ctx.folder`` and returns its relative path. ``label`` is
    what the GUI's export dialog says; ``cli`` the name ``--outputs`` lists (default ``key``);
    ``path`` the file each step writes, ``{cam}`` standing for the camera's name as file names
    spell it (:func:`~..validate.file_stem`): declared here so that two parts or two cameras
    that would write one file are refused before any work (:func:`check_output_names`)."""

    key: str
    label: str
    steps: Callable[[RegistrationResult, list[str]], list[tuple[str, float]]]
    write: Callable[[ExportContext, str, str, Reporter], str]
    cli: str = ""
    path: str = ""

    def file(self, cam: str = "") -> str:
        """The relative path this part writes for camera ``cam`` (``path`` filled in)."""
        return self.path.format(cam=file_stem(cam))


def _file(kind: str, cam: str = "") -> str:
    """The relative path the part ``kind`` writes for ``cam`` (from the registry)."""
    return next(p for p in OUTPUT_PARTS if p.key == kind).file(cam)


def _write_registered(ctx: ExportContext, kind: str, cam: str, rep: Reporter) -> str:
    # encoded in a background thread while the previews, the point cloud and the rest are made
    # here (the codecs release the GIL); waited for before the summary (_wait_background)
    rel = _file(kind, cam)
    ctx.timings.setdefault(kind, 0.0)
    if ctx.early is not None and ctx.early.has(cam, ctx.result.registered[cam], ctx.tiff_codec):
        ctx.background.submit(ctx.early.take, cam, ctx.folder / rel)  # waits for it, moves it in
    else:
        ctx.background.submit(write_registered_tiff, ctx.folder / rel, ctx.result.registered[cam], ctx.tiff_codec)
    return rel


def _wait_background(ctx: ExportContext, rep: Reporter, fraction: float) -> None:
    """Wait for the files written in the background (their errors are raised here)."""
    if ctx.background is not None and ctx.background.pending():
        rep(fraction, "writing registered images")
        ctx.timings["registered"] = ctx.timings.get("registered", 0.0) + ctx.background.wait()


def _write_preview(ctx: ExportContext, kind: str, cam: str, rep: Reporter) -> str:
    rel = _file(kind, cam)
    write_png(ctx.folder / rel, ctx.preview(cam))
    return rel


def _write_cases(ctx: ExportContext, kind: str, cam: str, rep: Reporter) -> str:
    rel = _file(kind, cam)
    write_png(ctx.folder / rel, np.asarray(ctx.result.cases[cam], dtype=np.uint8))
    return rel


def _write_areas(ctx: ExportContext, kind: str, cam: str, rep: Reporter) -> str:
    rel = _file(kind)
    write_png(ctx.folder / rel, np.asarray(ctx.result.area, dtype=np.uint8))
    return rel


def _write_pointcloud(ctx: ExportContext, kind: str, cam: str, rep: Reporter) -> str:
    colour_cam = _colour_camera(ctx.result, ctx.rig)
    rel = _file(kind)
    write_ply(ctx.folder / rel, ctx.result, ctx.cams, None if colour_cam is None else ctx.preview(colour_cam), rep)
    return rel


def _write_mosaic(ctx: ExportContext, kind: str, cam: str, rep: Reporter) -> str:
    tile = ctx.mosaic_tile or display.default_tile(ctx.result.shape)
    rel = _file(kind)
    write_png(ctx.folder / rel, display.mosaic([ctx.preview(c) for c in ctx.cams], tile))
    return rel


def _summary_draft(ctx: ExportContext) -> dict[str, Any]:
    """``summary.json`` but its export timings: made while the registered images are still being
    encoded in the background (case counts, mapped pixels: off the end of an export)."""
    return build_summary(ctx.result, ctx.rig, ctx.recording, ctx.inputs, export_timings={},
                         files=ctx.written + [_file("summary")])


def _write_summary(ctx: ExportContext, kind: str, cam: str, rep: Reporter) -> str:
    summary = ctx.summary_draft if ctx.summary_draft is not None else _summary_draft(ctx)
    ctx.timings["total"] = time.perf_counter() - ctx.t_start
    summary["export_timings"] = jsonable(dict(ctx.timings))
    rel = _file(kind)
    atomic_write_text(ctx.folder / rel, json.dumps(summary, indent=2, allow_nan=False) + "\n")
    return rel


def _write_mask(ctx: ExportContext, kind: str, cam: str, rep: Reporter) -> str:
    """``cases/<cam>_edge.png`` (kind ``edges``) or ``flying.png``; returns the relative path.
    Masks are uint8, 255 = flagged, so any viewer shows them."""
    rel = _file(kind, cam)
    mask = np.asarray(ctx.result.mixed[cam] if kind == "edges" else ctx.result.flying, dtype=bool)
    write_png(ctx.folder / rel, mask.view(np.uint8) * np.uint8(255))  # 0 / 255 (no int64 intermediate)
    return rel


#: The parts of the output, in writing order: the one place an output is declared. The command
#: line's ``--outputs``, the GUI's export dialog and the progress weights all read it; adding an
#: output = one :class:`OutputPart` here (the summary stays last: it lists the files written).
OUTPUT_PARTS: tuple[OutputPart, ...] = (
    OutputPart("registered", "Registered images (float32 TIFF, NaN = not mapped)",
               lambda r, cams: [(f"registered:{c}", 1.0 + 0.02 * _bands(r.registered[c])) for c in cams],
               _write_registered, path="registered/{cam}.tif"),
    OutputPart("previews", "Display previews (PNG, as shown here)",
               lambda r, cams: [(f"previews:{c}", 1.0 + 0.01 * _bands(r.registered[c])) for c in cams],
               _write_preview, path="registered/{cam}.png"),
    OutputPart("cases", "Case masks per source (PNG, codes 0-6)",
               lambda r, cams: [(f"cases:{c}", 0.3) for c in r.cases], _write_cases, path="cases/{cam}.png"),
    OutputPart("edges", "Mixed edge pixels per source (PNG mask)",
               lambda r, cams: [(f"edges:{c}", 0.3) for c in r.mixed], _write_mask, path="cases/{cam}_edge.png"),
    OutputPart("flying", "Flying depth pixels (PNG mask, the depth camera's grid)",
               lambda r, cams: [("flying", 0.2)] if r.flying is not None else [], _write_mask, path="flying.png"),
    OutputPart("areas", "Area mask of the target (PNG, codes 4-6)", lambda r, cams: [("areas", 0.3)], _write_areas,
               path="areas.png"),
    OutputPart("pointcloud", "Point cloud with every modality's values (PLY)",
               lambda r, cams: [("pointcloud", 2.0 + 0.05 * sum(_bands(r.registered[c]) for c in cams))],
               _write_pointcloud, cli="ply", path="pointcloud.ply"),
    # a recording with a depth map only has nothing to tile
    OutputPart("mosaic", "Mosaic of all modalities (PNG)", lambda r, cams: [("mosaic", 1.0)] if cams else [],
               _write_mosaic, path="mosaic.png"),
    OutputPart("summary", "Summary: inputs, parameters, case counts, timings (JSON)",
               lambda r, cams: [("summary", 0.0)], _write_summary, path="summary.json"),
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


def check_output_names(cameras: Iterable[str], what: Iterable[str] | None = None) -> None:
    """Refuse cameras whose outputs would share a file (compared ignoring case, as Windows and
    macOS do): every selected part's declared ``path`` for every camera, as in
    :data:`OUTPUT_PARTS` -- ``thermal``'s mixed-pixel mask ``cases/thermal_edge.png`` is the case
    map of a camera named ``thermal_edge``. Checked from the rig's names before any work (a part
    that writes a camera's file only for sources is checked for every camera: the refusal does
    not depend on the target chosen)."""
    sel = set(_keys()) if what is None else {_alias(w) for w in what}
    seen: dict[str, tuple[OutputPart, str]] = {}
    for part in OUTPUT_PARTS:
        if part.key not in sel or not part.path:
            continue
        for cam in (dict.fromkeys(cameras) if "{cam}" in part.path else [""]):
            rel = part.file(cam)
            other = seen.setdefault(rel.lower(), (part, cam))
            if other != (part, cam):
                o_part, o_cam = other

                def whose(p: OutputPart, c: str) -> str:
                    return f"'{p.cli or p.key}'" + (f" of camera '{c}'" if c else "")
                raise InputError(f"two outputs would be the same file {rel}: {whose(o_part, o_cam)} and "
                                 f"{whose(part, cam)} (parts as --outputs names them); rename one of these cameras "
                                 "in the rig")


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
    check_output_names([*cams, *result.cases], sel)
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
        from ..data.recording import recording_inputs

        # what registering it read, as `plantreg register` lists it (the manifest, ENVI data files)
        keep += [Path(recording.folder), *map(Path, recording.paths.values()), *recording_inputs(recording.folder)]
    with claim_output(out, "output", folder=True, overwrite=overwrite, inputs=keep), \
            atomic_output_dir(out, overwrite) as tmp, Background() as background:
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
            if rel.lower() in (w.lower() for w in ctx.written):  # a part without a declared path
                raise InputError(f"two outputs would be the same file {rel}; rename a camera in the rig", out)
            if kind != "summary":  # the summary holds the timings: it is written last, untimed
                ctx.timings[kind] = ctx.timings.get(kind, 0.0) + time.perf_counter() - t0
            ctx.written.append(rel)
            done += weight
        _wait_background(ctx, rep, done / total)
        rep.check()  # a cancel during the last file still leaves nothing behind
    if not rep.cancel.cancelled:  # the folder is complete now: a late cancel changes nothing
        rep(1.0, f"wrote {out}")
    return out


# ---------------------------------------------------------------------- mixed-pixel and flying-pixel masks


# ---------------------------------------------------------------------- registered images
# ---------------------------------------------------------------------- point cloud


# ---------------------------------------------------------------------- summary


# ---------------------------------------------------------------------- helpers
def _modality(rig: Rig, name: str) -> str | None:
    c = rig_camera(rig, name)
    return c.modality if c is not None else None


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
    part = next((p for p in OUTPUT_PARTS if p.key == kind), None)
    return part.file(cam) if part is not None and part.path else kind


__all__ = ["EarlyTiffs", "OUTPUTS", "OUTPUT_PARTS", "OutputPart", "check_output_names", "parse_outputs",
           "write_outputs", "write_ply", "build_summary", "ply_property_names"]
