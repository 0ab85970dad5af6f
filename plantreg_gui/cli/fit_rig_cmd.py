"""``plantreg fit-rig``: fit a rig's cameras to landmarks clicked in the recordings themselves.

    plantreg fit-rig --rig START --landmarks LANDMARKS.json --out RIG
                     [--free focal,principal,k1] [--refine] [--silhouette] [--recording DIR ...] [--overwrite] [--quiet]

Writes a normal rig file whose ``"calibration"`` entry records the method, the landmarks used,
every residual and the leave-one-recording-out residuals, and prints the per-camera residual
table with the worst landmarks (see docs/fit-rig.md).
"""

from __future__ import annotations

import argparse
import sys
from datetime import datetime, timezone
from pathlib import Path

from ..core.errors import InputError


def add_parser(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "fit-rig",
        help="fit camera poses (and optionally intrinsics) from landmark pairs",
        description="Fit every camera's pose -- and, with --free, focal length, principal point and first "
        "radial distortion term, the depth camera's included -- to landmarks: depth-camera pixels and the "
        "same points clicked in other cameras (a plantreg.landmarks JSON file). All recordings are fitted "
        "jointly, robustly, with weak priors towards the start rig.",
    )
    p.add_argument("--rig", required=True, type=Path, metavar="START", help="start rig (plantreg.rig JSON)")
    p.add_argument("--landmarks", required=True, type=Path, metavar="LANDMARKS.json",
                   help="landmarks file (plantreg.landmarks JSON; recording paths relative to it)")
    from . import nonempty_path

    p.add_argument("--out", required=True, type=nonempty_path, metavar="RIG", help="fitted rig file to write")
    p.add_argument("--free", default="", metavar="ITEMS",
                   help="intrinsics to fit: comma-separated focal, principal, k1 (every camera, the depth camera "
                        "included) or CAMERA:ITEM for one camera, e.g. 'focal,ir:k1,ir:principal'")
    p.add_argument("--refine", action="store_true",
                   help="then refine the rig automatically from the images (see docs/fit-rig.md)")
    p.add_argument("--silhouette", action="store_true",
                   help="then fit every camera's pose to the plant outline in all recordings, with the landmarks "
                        "as a term (core/rigfit/silhouette.py; see docs/fit-rig.md)")
    p.add_argument("--recording", action="append", type=Path, default=[], metavar="DIR",
                   help="more recordings for --refine / --silhouette (repeatable)")
    p.add_argument("--worst", type=int, default=10, metavar="N", help="worst landmarks to list (default 10)")
    p.add_argument("--overwrite", action="store_true", help="replace RIG if it exists")
    p.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    p.set_defaults(run=run)
    return p


def run(args: argparse.Namespace) -> int:
    from .. import cli
    from ..core.data.landmarks import LandmarkSet
    from ..core.camera.rig import Rig
    from ..core.data.recording import recording_inputs
    from ..core.io.paths import check_output_location
    from ..core.rigfit.rigfit import fit_rig_from_file, format_report, parse_free

    out: Path = args.out
    if args.recording and not (args.refine or args.silhouette):
        raise InputError("--recording adds recordings for --refine or --silhouette; pass one of them too")
    free = parse_free(args.free)
    rig = Rig.load(args.rig)
    try:
        rig.depth()
    except InputError as e:
        raise InputError(f"{e.detail}; a landmark fit needs the depth camera", args.rig) from None
    landmarks = LandmarkSet.load(args.landmarks)
    # the output, before the fit: never the start rig, the landmarks or a file of their recordings
    reads = [f for key in landmarks.recordings for f in recording_inputs(landmarks.folder(key))]
    reads += [f for folder in args.recording for f in recording_inputs(folder)]
    check_output_location(out, "output rig", overwrite=args.overwrite, inputs=[args.rig, args.landmarks, *reads])
    if landmarks.count() > 0:
        result = fit_rig_from_file(rig, landmarks, free=free)
        fitted, report, warnings = result.rig, result.report, list(result.warnings)
        method = "landmarks"
    elif args.refine or args.silhouette:  # no points: refine from the images alone, starting from the start rig
        landmarks.check_recordings()
        fitted, report, warnings, method = rig, {"landmarks_used": 0}, [], ("refine" if args.refine else "start")
    else:
        raise InputError("the landmarks file has no points (add some, or pass --refine or --silhouette to fit "
                         "from the images alone)", args.landmarks)
    if args.refine or args.silhouette:
        recordings, by_folder = _recordings(args, landmarks, fitted)  # read once for both
    if args.refine:
        # the refinement is its own module (core/rigfit/refine.py); imported only when asked for
        from ..core.rigfit.refine import refine_rig
        from ..core.progress import Reporter

        rr = refine_rig(fitted, recordings, free=free, landmarks=by_folder,
                        progress=Reporter(cli.StderrProgress(quiet=args.quiet)))
        fitted, method = rr.rig, ("landmarks+refine" if report.get("landmarks_used") else "refine")
        report["refine"] = rr.report
        warnings += list(rr.warnings)
    if args.silhouette:
        fitted, method = _silhouette(args, fitted, recordings, by_folder, report, method)
    previous = rig.extra.get("calibration")
    fitted.extra["calibration"] = {
        "method": method,
        "date": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "command": "plantreg " + " ".join(getattr(args, "argv", []) or sys.argv[1:]),
        "start_rig": str(Path(args.rig).resolve()),
        "landmarks_file": str(Path(args.landmarks).resolve()),
        **{k: v for k, v in report.items() if k not in ("time_s", "method")},
        "warnings": warnings,
        **({"previous_method": previous.get("method")} if isinstance(previous, dict) and previous.get("method")
           else {}),
    }
    fitted.save(out)
    if report.get("landmarks_used"):
        print(format_report(report, worst=args.worst))
    if "refine" in report:
        print("refinement: see \"calibration\".\"refine\" in the rig file")
    if "silhouette" in report:
        print(_silhouette_table(report["silhouette"]))
    for w in warnings:
        print(f"warning: {w}", file=sys.stderr)
    print(f"wrote {out}")
    return 0


def _recordings(args: argparse.Namespace, landmarks, rig) -> tuple[list, dict]:
    """The landmark file's recordings and any --recording DIR, read against ``rig``; the
    landmarks keyed by absolute folder (they match the recordings whatever the landmarks file's
    relative paths)."""
    from ..core.data.recording import Recording

    from ..core.io.paths import resolve

    folders = [resolve(landmarks.folder(k), "recording folder") for k in landmarks.recordings]
    folders += [f for f in (resolve(d, "--recording") for d in args.recording) if f not in folders]
    recordings = [Recording.load(f, rig) for f in folders]
    by_folder = {str(resolve(landmarks.folder(k))): pts for k, pts in landmarks.recordings.items()}
    return recordings, by_folder


def _silhouette(args: argparse.Namespace, fitted, recordings: list, by_folder: dict, report: dict, method: str):
    """--silhouette: outline fit over the recordings (see :func:`_recordings`)."""
    from .. import cli
    from ..core.progress import Reporter
    from ..core.rigfit.silhouette import fit_rig_recordings

    progress = Reporter(cli.StderrProgress(quiet=args.quiet))
    rig, srep = fit_rig_recordings(fitted, recordings, by_folder, progress=progress)
    report["silhouette"] = srep
    return rig, ("silhouette" if method == "start" else method + "+silhouette")


def _silhouette_table(rep: dict) -> str:
    import numpy as np

    lines = ["silhouette fit:",
             "  camera          recordings  outline median px  landmarks median px (before -> after)"]
    for name, r in rep["cameras"].items():
        med = [v["outline_median_px"] for v in r["views"].values() if "outline_median_px" in v]
        b = [e for v in r["views"].values() for e in v.get("landmarks_px", [])]
        a = [e for v in r["views"].values() for e in v.get("landmarks_px_after", [])]
        lm = f"{np.median(b):.2f} -> {np.median(a):.2f} (n {len(a)})" if a else "-"
        lines.append(f"  {name:<15} {len(r['views']):>10}  {np.median(med) if med else float('nan'):>17.2f}  {lm}")
    return "\n".join(lines)
