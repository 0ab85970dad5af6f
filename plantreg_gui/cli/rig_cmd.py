"""``plantreg rig create``: a start rig for ``plantreg fit-rig`` from what a user knows.

    plantreg rig create OUT --depth-camera NAME --camera NAME=MODALITY,WxH,LENS,rot=A[,at=X,Y,Z] ...
                        [--depth-scale S] [--roi XMIN,YMIN,ZMIN,XMAX,YMAX,ZMAX] [--overwrite]

LENS is ``hfov=DEG[,vfov=DEG]``, ``f=PX[,fy=PX]`` or ``kinect=CALIBRATION.json`` (the Azure
Kinect's raw factory calibration, converted to the depth mode of the given size); see
:mod:`..core.rigfit.start` and docs/fit-rig.md.
"""

from __future__ import annotations

import argparse
import sys

from ..core.errors import InputError


def add_parser(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser("rig", help="make a start rig from camera data sheets (rig create)",
                       description="Rig files: a start rig from what you know about the cameras.")
    rs = p.add_subparsers(dest="rig_command", metavar="ACTION", required=True)
    c = rs.add_parser(
        "create", help="write a start rig for fit-rig",
        description="Write a start rig (plantreg.rig JSON) for plantreg fit-rig from camera models: size, a "
        "lens (data sheet field of view, a focal length in pixels, or the Azure Kinect's factory calibration), "
        "how each image is turned against the depth camera's and a rough position.")
    from . import nonempty_path

    c.add_argument("out", type=nonempty_path, metavar="OUT", help="rig file to write")
    c.add_argument("--depth-camera", required=True, metavar="NAME", help="the camera the depth maps belong to")
    c.add_argument("--camera", action="append", required=True, default=[], metavar="SPEC",
                   help="NAME=MODALITY,WxH,LENS,rot=0|90|180|270[,at=X,Y,Z] with LENS hfov=DEG[,vfov=DEG] | "
                        "f=PX[,fy=PX] | kinect=CALIBRATION.json | kinect=typical; rot = degrees the scene appears turned "
                        "anticlockwise against the depth camera's image; at = optical centre in metres in the "
                        "depth camera's frame (x right, y down, z forward). Repeat per camera.")
    c.add_argument("--depth-scale", type=float, default=0.001, metavar="S", help="metres per depth unit (0.001)")
    c.add_argument("--roi", metavar="XMIN,YMIN,ZMIN,XMAX,YMAX,ZMAX",
                   help="region of interest in the depth camera's frame, metres; ZMAX is the ground")
    c.add_argument("--overwrite", action="store_true", help="replace OUT if it exists")
    c.set_defaults(run=run_create)
    return p


def run_create(args: argparse.Namespace) -> int:
    from ..core.rigfit.start import create_rig, parse_camera_spec
    from .fit_rig_cmd import claim_output_rig

    specs = [parse_camera_spec(t) for t in args.camera]
    kinect = [s.kinect for s in specs if s.kinect is not None]
    roi = None
    if args.roi is not None:
        try:
            v = [float(x) for x in args.roi.split(",")]
        except ValueError:
            v = []
        if len(v) != 6:
            raise InputError(f"--roi takes six numbers XMIN,YMIN,ZMIN,XMAX,YMAX,ZMAX in metres, got '{args.roi}'")
        roi = (v[:3], v[3:])
    with claim_output_rig(args.out, args.overwrite, kinect):
        rig, warnings = create_rig(specs, args.depth_camera, args.depth_scale, roi)
        rig.save(args.out)
    for c in rig.cameras:
        print(f"  {c.name:<14} {c.modality:<13} {c.width}x{c.height}  fx {c.K[0, 0]:.1f} fy {c.K[1, 1]:.1f}  "
              f"centre ({c.center_rig[0]:+.3f}, {c.center_rig[1]:+.3f}, {c.center_rig[2]:+.3f}) m  "
              f"[{c.extra.get('intrinsics_source', '')}]")
    for w in warnings:
        print(f"warning: {w}", file=sys.stderr)
    print(f"wrote {args.out}")
    return 0
