"""The one load -> register -> write pipeline: ``plantreg register``, ``plantreg batch`` and the
GUI's workspace all call these functions, so an option exists for all of them or for none.

* :func:`register` -- a :class:`~..registration.register.Registrar` (new, or the caller's, whose
  meshes are reused) registers a recording into one target camera.
* :func:`export` -- writes a result into an output folder (:func:`~..export.export.write_outputs`)
  with the :class:`OutputOptions`, including ``drop_mixed`` (NaN where a pixel is flagged mixed).
* :func:`register_recording` -- both, from a rig and a recording folder: what the command line
  and every batch job run.
"""

from __future__ import annotations

import time
from contextlib import nullcontext
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Callable, Mapping

import numpy as np

from ..camera.rig import Rig
from ..data.recording import Recording
from ..export.export import EarlyTiffs, write_outputs
from ..io.imageio import TIFF_CODEC_DEFAULT
from ..progress import Reporter, ensure_reporter
from ..registration.hits import HitImage
from ..registration.params import RegistrationParams, RegistrationResult
from ..registration.register import Registrar


@dataclass
class OutputOptions:
    """What :func:`export` writes. ``parts``: keys of :data:`~..export.export.OUTPUT_PARTS` (None =
    all); ``tiff_codec`` the registered TIFFs' compression; ``drop_mixed``: NaN instead of the
    registered value where a pixel is flagged mixed (per source); ``display_options`` and
    ``mosaic_tile`` make the previews look like a screen (:func:`~..export.export.write_outputs`)."""

    parts: tuple[str, ...] | None = None
    tiff_codec: str = TIFF_CODEC_DEFAULT
    drop_mixed: bool = False
    display_options: Mapping[str, Mapping[str, Any]] | None = None
    mosaic_tile: int | None = None


def register(rig: Rig, recording: Recording, target: str, params: RegistrationParams | None = None,
             progress: Reporter | None = None, *, registrar: Registrar | None = None,
             on_image: Callable[[str, Any], None] | None = None,
             ray_cache: tuple[dict, dict] | None = None) -> tuple[Registrar, RegistrationResult]:
    """Register every camera of ``recording`` into ``target``'s view: (the registrar, its result).

    ``registrar``: one made earlier for this rig and recording (its meshes are reused; ``params``
    is then ignored). ``ray_cache``: pixel rays shared between registrars of the same rig
    (:meth:`~..registration.register.Registrar.ray_cache`; a batch worker keeps them between
    jobs). ``on_image``: see :meth:`~..registration.register.Registrar.register`.
    """
    if registrar is None:
        registrar = Registrar(rig, recording, (params or RegistrationParams()).validate())
        if ray_cache is not None:
            registrar.use_ray_cache(ray_cache)
    return registrar, registrar.register(target, progress, on_image=on_image)


def without_mixed(result: RegistrationResult, in_place: bool = False) -> RegistrationResult:
    """The result with NaN as registered value where a pixel is flagged mixed (per source).
    ``in_place``: change ``result``'s own images (a caller that owns them: no copies); else a
    shallow copy of the result whose changed images are copies (the GUI keeps showing its own)."""
    registered = result.registered if in_place else dict(result.registered)
    for cam, m in result.mixed.items():
        if cam not in registered or not np.any(m):
            continue
        img = registered[cam]
        flagged = np.asarray(m, dtype=bool)
        if isinstance(img, HitImage):
            if not in_place:
                img = HitImage(img.index, img.values.copy(), img.shape)
            img.values[flagged.reshape(-1)[img.index]] = np.nan
        else:
            if not in_place:
                img = np.array(img, copy=True)
            img[flagged] = np.nan
        registered[cam] = img
    return result if in_place else replace(result, registered=registered)


def export(result: RegistrationResult, rig: Rig, recording: Recording | None, out: str | Path,
           options: OutputOptions | None = None, *, overwrite: bool = False, inputs: dict[str, Any] | None = None,
           progress: Reporter | None = None, owned: bool = False, early: EarlyTiffs | None = None) -> Path:
    """Write ``result`` into the folder ``out`` as ``options`` say; returns ``out``.
    ``owned``: the caller will not use ``result`` again (``drop_mixed`` changes it in place)."""
    options = options or OutputOptions()
    if options.drop_mixed:
        result = without_mixed(result, in_place=owned)
    return write_outputs(result, rig, recording, out, overwrite=overwrite, progress=progress, inputs=inputs,
                         what=options.parts, display_options=options.display_options,
                         tiff_codec=options.tiff_codec, mosaic_tile=options.mosaic_tile, early=early)


@dataclass
class PipelineRun:
    """What :func:`register_recording` did: the result and the seconds of each stage."""

    result: RegistrationResult
    recording: Recording
    registrar: Registrar
    seconds: dict[str, float] = field(default_factory=dict)  # read, register, write


def register_recording(rig: Rig, recording: Recording | str | Path, target: str, out: str | Path,
                       params: RegistrationParams | None = None, options: OutputOptions | None = None, *,
                       overwrite: bool = False, inputs: dict[str, Any] | None = None,
                       progress: Reporter | None = None, encode_early: bool = True,
                       ray_cache: tuple[dict, dict] | None = None) -> PipelineRun:
    """Load (a folder), register into ``target`` and write ``out``: the whole pipeline.

    ``encode_early``: the registered TIFFs are encoded while the other sources are still being
    registered (:class:`~..export.export.EarlyTiffs`; a single run has a core to spare, a batch
    worker has not). Open3D's extension loads while the images decode.
    """
    from ..geometry.o3d_core import load_in_background

    options = options or OutputOptions()
    progress = ensure_reporter(progress)
    parts = options.parts
    early = (EarlyTiffs(out, options.tiff_codec)
             if encode_early and (parts is None or "registered" in parts) and not options.drop_mixed else None)
    seconds: dict[str, float] = {}
    loading: list = []
    with early or nullcontext():
        try:
            t = time.perf_counter()
            if not isinstance(recording, Recording):
                # the extension loads in a thread (GIL held) while the images decode (GIL
                # released); joined always, so no error exits mid-load
                recording = Recording.load(recording, rig, while_decoding=lambda: loading.append(load_in_background()))
            seconds["read"] = time.perf_counter() - t
            t = time.perf_counter()
            registrar, result = register(rig, recording, target, params, progress.sub(0.0, 0.85),
                                         on_image=early, ray_cache=ray_cache)
            seconds["register"] = time.perf_counter() - t
        finally:
            for th in loading:
                th.join()
        t = time.perf_counter()
        export(result, rig, recording, out, options, overwrite=overwrite, inputs=inputs,
               progress=progress.sub(0.85, 1.0), owned=True, early=early)
        seconds["write"] = time.perf_counter() - t
    return PipelineRun(result, recording, registrar, seconds)


__all__ = ["OutputOptions", "PipelineRun", "register", "export", "without_mixed", "register_recording"]
