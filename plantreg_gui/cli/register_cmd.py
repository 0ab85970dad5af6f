"""``plantreg register``: register every camera of a recording into one target camera's view.

    plantreg register --rig RIG --recording DIR --target NAME --out OUT
                      [--edge-angle DEG] [--outputs PARTS] [--tiff-codec C] [--overwrite] [--quiet]
                      [--no-flying-filter | --remove-flying] [--flying-jump REL]
                      [--no-fill-holes] [--no-denoise] [--denoise-size N] [--mixed-radius PX] [--drop-mixed]

Writes the output folder described in ``docs/outputs.md`` (see :mod:`plantreg_gui.core.export.export`)
and prints, per source camera, the share of target pixels in each projection case.
Progress goes to stderr (``--quiet`` silences it); the summary goes to stdout.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from ..core.errors import InputError
from ..core.progress import Reporter


def add_parser(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "register",
        help="register all cameras of a recording into a target camera's view",
        description="Register all cameras of a recording into the view of one target camera "
        "(3D: depth mesh + ray casting) and write registered images, case maps, a point cloud "
        "and a summary into OUT.",
    )
    from . import nonempty_path

    p.add_argument("--rig", required=True, type=nonempty_path, metavar="RIG", help="rig file (plantreg.rig JSON)")
    p.add_argument("--recording", required=True, type=nonempty_path, metavar="DIR",
                   help="recording folder (with recording.json)")
    p.add_argument("--target", required=True, metavar="NAME", help="name of the target camera")
    p.add_argument("--out", required=True, type=nonempty_path, metavar="OUT", help="output folder (must not exist or be empty)")
    add_registration_options(p)
    add_output_options(p)
    p.add_argument("--overwrite", action="store_true", help="replace OUT if it exists")
    p.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    p.set_defaults(run=run)
    return p


def add_output_options(p: argparse.ArgumentParser) -> None:
    """The output options ``plantreg register`` and ``plantreg batch`` share."""
    # the parts are core.export.export.OUTPUT_PARTS; not listed here: importing it would slow every --help
    p.add_argument("--outputs", default=None, metavar="PARTS",
                   help="comma-separated parts of the output to write, e.g. registered,cases,ply (default: "
                   "all; an unknown name lists every part)")
    p.add_argument("--tiff-codec", default="deflate-fp", choices=("deflate-fp", "deflate", "zstd"),
                   help="lossless compression of the registered TIFFs (default deflate-fp: deflate with the "
                   "floating-point predictor; zstd is faster but not read by ImageJ/Fiji)")
    mixed = p.add_argument_group("mixed pixels in the outputs")
    mixed.add_argument("--drop-mixed", action="store_true",
                       help="write NaN instead of the registered value where a pixel is flagged mixed")


def output_options(args: argparse.Namespace):
    """:class:`~plantreg_gui.core.pipeline.pipeline.OutputOptions` from :func:`add_output_options`'s options."""
    from ..core.export.export import parse_outputs
    from ..core.pipeline.pipeline import OutputOptions

    return OutputOptions(parts=parse_outputs(args.outputs), tiff_codec=args.tiff_codec,
                         drop_mixed=bool(args.drop_mixed))


def add_registration_options(p: argparse.ArgumentParser) -> None:
    """The registration parameters ``plantreg register`` and ``plantreg batch`` share
    (read back by :func:`registration_params`)."""
    from . import finite_float

    p.add_argument("--edge-angle", type=finite_float, default=None, metavar="DEG",
                   help="mesh edge-cut angle in degrees (default 15, as in the paper)")
    tof = p.add_argument_group("time-of-flight depth clean-up and mixed pixels (docs/registration.md)")
    fly = tof.add_mutually_exclusive_group()
    fly.add_argument("--no-flying-filter", action="store_true",
                     help="keep flying pixels (depths between two surfaces) as measured")
    fly.add_argument("--remove-flying", action="store_true",
                     help="remove flying pixels instead of moving them onto the surface they mostly saw")
    tof.add_argument("--flying-jump", type=finite_float, default=None, metavar="REL",
                     help="a depth jump between neighbours counts above REL x depth (default 0.01: 1 cm at 1 m)")
    tof.add_argument("--no-fill-holes", action="store_true",
                     help="leave holes in the depth (no measurement) as they are; by default a hole between "
                          "two measured pixels of one surface is filled by interpolation")
    tof.add_argument("--no-denoise", action="store_true", help="no edge-preserving depth denoising")
    tof.add_argument("--denoise-size", type=int, default=None, metavar="N",
                     help="window of the same-surface plane fit, depth pixels, odd (default 3)")
    tof.add_argument("--mixed-radius", type=finite_float, default=None, metavar="PX",
                     help="mixed-pixel flag: source pixels around a silhouette, before adding 2 x the "
                          "camera's blur_px (default 1)")


def load_rig_for_target(rig_path: Path, target: str, parts: tuple[str, ...] | None = None):
    """The rig at ``rig_path``, checked to have a depth camera and a camera ``target``, and
    camera names whose output ``parts`` (None = all) are distinct files."""
    from ..core.camera.rig import Rig
    from ..core.export.export import check_output_names

    rig = Rig.load(rig_path)
    # the rig's own errors do not know its file name: add it
    try:
        rig.depth()
    except InputError as e:
        raise InputError(f"{e.detail}; registration needs a depth camera", rig_path) from None
    if target not in rig.names:
        raise InputError(f"unknown target camera '{target}'; the rig has {', '.join(rig.names)}", rig_path)
    try:
        check_output_names(rig.names, parts)
    except InputError as e:
        raise InputError(e.detail, rig_path) from None
    return rig


#: Options that set a registration parameter: option attribute -> (parameter, type).
_VALUE_OPTIONS = {"edge_angle": ("edge_angle_deg", float), "flying_jump": ("flying_jump_rel", float),
                  "denoise_size": ("denoise_size", int), "mixed_radius": ("mixed_radius_px", float)}
#: Switches that turn a registration parameter off: option attribute -> parameter.
_OFF_SWITCHES = {"no_flying_filter": "flying_filter", "remove_flying": "flying_repair",
                 "no_fill_holes": "fill_holes", "no_denoise": "denoise"}
#: The command-line option of each registration parameter (named in range errors).
OPTION_NAMES = {field: "--" + opt.replace("_", "-") for opt, (field, _t) in _VALUE_OPTIONS.items()}


def registration_params(args: argparse.Namespace):
    """:class:`RegistrationParams` from the options of :func:`add_registration_options`, checked
    against the parameters' one table of ranges (``RegistrationParams.validate``)."""
    from ..core.registration.params import RegistrationParams

    params = RegistrationParams()
    for opt, (field, kind) in _VALUE_OPTIONS.items():
        if getattr(args, opt) is not None:
            setattr(params, field, kind(getattr(args, opt)))
    for opt, field in _OFF_SWITCHES.items():
        if getattr(args, opt):
            setattr(params, field, False)
    return params.validate(OPTION_NAMES)


def run(args: argparse.Namespace) -> int:
    from .. import cli
    from ..core.data.recording import recording_inputs
    from ..core.io.lock import claim_output
    from ..core.io.paths import resolve
    from ..core.pipeline.pipeline import register_recording
    from ..core.registration.cases import Area, Case

    rig_path: Path = args.rig
    out: Path = args.out
    options = output_options(args)
    rig = load_rig_for_target(rig_path, args.target, options.parts)
    params = registration_params(args)
    # fail before the long work, not after it: the output location (free or --overwrite, not an
    # input, writable), then the recording (names, then every image's header and size)
    recording = resolve(args.recording, "recording folder")
    progress = Reporter(cli.StderrProgress(quiet=args.quiet))
    # checked, then locked (a second run writing OUT, or inside it, meanwhile is refused: core/io/lock.py)
    with claim_output(out, "output", folder=True, overwrite=args.overwrite,
                      inputs=[rig_path, *recording_inputs(recording)]):
        result = register_recording(rig, args.recording, args.target, out, params, options, overwrite=args.overwrite,
                                    inputs={"rig": rig_path.resolve(), "recording": recording,
                                            "command": _command_line(args)}, progress=progress).result

    H, W = result.shape
    n = H * W
    print(f"registered into '{result.target}' ({W}x{H}); wrote {out}")
    for w in result.warnings:
        print(f"warning: {w}", file=sys.stderr)
    for cam, counts in result.case_counts().items():
        # P1, P2, P3.1, P3.2, P5, P6 background, outside the source: % of all target pixels
        parts = [f"{c.short} {100.0 * counts.get(int(c), 0) / n:5.1f}%" for c in
                 (Case.P1, Case.P2, Case.P31, Case.P32, Case.P5, Case.BACKGROUND, Case.OUTSIDE)]
        print(f"  {cam}: " + "  ".join(parts))
    a = np.asarray(result.area)
    print("  target areas: " + "  ".join(
        f"{code.short} {100.0 * float(np.count_nonzero(a == code)) / n:5.1f}%" for code in (Area.P4, Area.P5, Area.P6)))
    if result.flying is not None:
        how = "off" if not params.flying_filter else ("repaired" if params.flying_repair else "removed")
        print(f"  depth: {int(np.count_nonzero(result.flying))} flying pixels ({how}), "
              f"{int(result.stats.get('filled_pixels', 0))} holes filled"
              + ("; mixed (% of P1): " + "  ".join(
                  f"{cam} {100.0 * np.count_nonzero(m) / max(1, np.count_nonzero(result.cases[cam] == 1)):.1f}%"
                  for cam, m in result.mixed.items()) if result.mixed else ""))
    return 0


def _command_line(args: argparse.Namespace) -> str:
    parts = ["plantreg", "register", "--rig", str(args.rig), "--recording", str(args.recording),
             "--target", args.target, "--out", str(args.out)]
    if args.edge_angle is not None:
        parts += ["--edge-angle", f"{args.edge_angle:g}"]
    for flag in ("no_flying_filter", "remove_flying", "no_denoise", "drop_mixed"):
        if getattr(args, flag, False):
            parts.append("--" + flag.replace("_", "-"))
    for opt in ("flying_jump", "denoise_size", "mixed_radius"):
        if getattr(args, opt, None) is not None:
            parts += ["--" + opt.replace("_", "-"), f"{getattr(args, opt):g}"]
    if args.outputs is not None:
        parts += ["--outputs", args.outputs]
    if args.tiff_codec != "deflate-fp":
        parts += ["--tiff-codec", args.tiff_codec]
    if args.overwrite:
        parts.append("--overwrite")
    return " ".join(parts)
