"""``plantreg demo DIR``: write the synthetic demo (rig, recording, ground truth, calibration session)."""

from __future__ import annotations

import argparse
import sys
import time

from . import StderrProgress


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "demo",
        help="write a synthetic rig, plant recording and ground truth to DIR",
        description="Write the synthetic demo: a rig placed like the paper's (depth + infrared, RGB, thermal, "
        "hyperspectral), a recording of a plant with overlapping curved leaves, the true registration of every "
        "infrared pixel (ground_truth/ir.npz) and a synthetic calibration session.",
    )
    from . import nonempty_path, nonneg_int

    p.add_argument("dir", type=nonempty_path, metavar="DIR", help="output folder (must not exist or be empty, unless --overwrite)")
    p.add_argument("--size", choices=("demo", "paper"), default="demo",
                   help="'demo': RGB 1280x720, hyperspectral 256x256x100; 'paper': RGB 3840x2160, "
                        "hyperspectral 512x512x204 (as in the paper's benchmark)")
    p.add_argument("--seed", type=nonneg_int, default=0, help="plant and noise seed (default 0)")
    p.add_argument("--clean", action="store_true",
                   help="ideal recording: exact depth (1 mm steps) and sharp images; by default the depth has "
                        "time-of-flight artefacts (flying pixels, holes, 1 mm + 0.1 %% noise) and the thermal "
                        "camera an optical blur")
    p.add_argument("--overwrite", action="store_true", help="replace DIR if it exists and is not empty")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress on stderr")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from ..core.synthetic import write_demo

    from ..core.io.lock import claim_output

    d = args.dir
    t0 = time.perf_counter()
    with claim_output(d, "demo folder", folder=True, overwrite=args.overwrite):
        paths = write_demo(args.dir, size=args.size, seed=args.seed, progress=StderrProgress(args.quiet),
                           overwrite=args.overwrite, clean=args.clean)
    print(f"wrote the synthetic demo to {d} in {time.perf_counter() - t0:.1f} s:")
    for name, p in paths.items():
        print(f"  {name:13s} {p}")
    print("next, register every camera into the infrared view:")
    print(f"  plantreg register --rig {d / 'rig.json'} --recording {d / 'recording'} --target ir --out {d / 'out'}")
    sys.stdout.flush()
    return 0
