"""``plantreg register``: register every camera of a recording into one target camera's view.

    plantreg register --rig RIG --recording DIR --target NAME --out OUT
                      [--edge-angle DEG] [--outputs PARTS] [--tiff-codec C] [--overwrite] [--quiet]

Writes the output folder described in ``docs/outputs.md`` (see :mod:`plantreg_gui.core.export`)
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
    p.add_argument("--rig", required=True, type=Path, metavar="RIG", help="rig file (plantreg.rig JSON)")
    p.add_argument("--recording", required=True, type=Path, metavar="DIR",
                   help="recording folder (with recording.json)")
    p.add_argument("--target", required=True, metavar="NAME", help="name of the target camera")
    p.add_argument("--out", required=True, type=Path, metavar="OUT", help="output folder (must not exist or be empty)")
    p.add_argument("--edge-angle", type=float, default=None, metavar="DEG",
                   help="mesh edge-cut angle in degrees (default 15, as in the paper)")
    add_output_options(p)
    p.add_argument("--overwrite", action="store_true", help="replace OUT if it exists")
    p.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    p.set_defaults(run=run)
    return p


def add_output_options(p: argparse.ArgumentParser) -> None:
    """The output options ``plantreg register`` and ``plantreg batch`` share."""
    p.add_argument("--outputs", default=None, metavar="PARTS",
                   help="comma-separated parts of the output to write: registered,cases,areas,ply,previews,"
                   "mosaic,summary (default: all)")
    p.add_argument("--tiff-codec", default="deflate-fp", choices=("deflate-fp", "deflate", "zstd"),
                   help="lossless compression of the registered TIFFs (default deflate-fp: deflate with the "
                   "floating-point predictor; zstd is faster but not read by ImageJ/Fiji)")


def run(args: argparse.Namespace) -> int:
    from .. import cli
    from ..core.export import check_output_spares_inputs, parse_outputs, write_outputs
    from ..core.recording import Recording
    from ..core.register import AREA_P4, AREA_P5, AREA_P6, Registrar, RegistrationParams
    from ..core.rig import Rig

    rig_path: Path = args.rig
    out: Path = args.out
    rig = Rig.load(rig_path)
    # the rig's own errors do not know its file name: add it
    try:
        rig.depth()
    except InputError as e:
        raise InputError(f"{e.detail}; registration needs a depth camera", rig_path) from None
    if args.target not in rig.names:
        raise InputError(f"unknown target camera '{args.target}'; the rig has {', '.join(rig.names)}", rig_path)
    what = parse_outputs(args.outputs)
    params = RegistrationParams()
    if args.edge_angle is not None:
        if not 0.0 < args.edge_angle < 90.0:
            raise InputError(f"--edge-angle must be between 0 and 90 degrees, got {args.edge_angle:g}")
        params.edge_angle_deg = float(args.edge_angle)
    # fail before the long work, not after it
    check_output_spares_inputs(out, [rig_path, args.recording])
    if out.exists() and not out.is_dir():
        raise InputError("output path exists and is not a folder", out)
    parent = out.absolute().parent
    while not parent.exists():
        parent = parent.parent
    if not parent.is_dir():
        raise InputError("output folder cannot be made: this is a file, not a folder", parent)
    if out.is_dir() and any(out.iterdir()) and not args.overwrite:
        raise InputError("output folder exists and is not empty (choose another, or pass --overwrite)", out)
    recording = Recording.load(args.recording, rig)

    progress = Reporter(cli.StderrProgress(quiet=args.quiet))
    result = Registrar(rig, recording, params).register(args.target, progress.sub(0.0, 0.85))
    write_outputs(result, rig, recording, out, overwrite=args.overwrite, progress=progress.sub(0.85, 1.0), what=what,
                  tiff_codec=args.tiff_codec,
                  inputs={"rig": rig_path.resolve(), "recording": Path(args.recording).resolve(),
                          "command": _command_line(args)})

    H, W = result.shape
    n = H * W
    print(f"registered into '{result.target}' ({W}x{H}); wrote {out}")
    for w in result.warnings:
        print(f"warning: {w}", file=sys.stderr)
    for cam, counts in result.case_counts().items():
        # P1, P2, P3.1, P3.2, P5, P6 background, outside the source: % of all target pixels
        parts = [f"{_SHORT[c]} {100.0 * counts.get(c, 0) / n:5.1f}%" for c in (1, 2, 3, 4, 5, 0, 6)]
        print(f"  {cam}: " + "  ".join(parts))
    a = np.asarray(result.area)
    print("  target areas: " + "  ".join(
        f"{name} {100.0 * float(np.count_nonzero(a == code)) / n:5.1f}%" for code, name in
        ((AREA_P4, "P4"), (AREA_P5, "P5"), (AREA_P6, "P6"))))
    return 0


_SHORT = {0: "P6", 1: "P1", 2: "P2", 3: "P3.1", 4: "P3.2", 5: "P5", 6: "outside"}


def _command_line(args: argparse.Namespace) -> str:
    parts = ["plantreg", "register", "--rig", str(args.rig), "--recording", str(args.recording),
             "--target", args.target, "--out", str(args.out)]
    if args.edge_angle is not None:
        parts += ["--edge-angle", f"{args.edge_angle:g}"]
    if args.outputs is not None:
        parts += ["--outputs", args.outputs]
    if args.tiff_codec != "deflate-fp":
        parts += ["--tiff-codec", args.tiff_codec]
    if args.overwrite:
        parts.append("--overwrite")
    return " ".join(parts)
