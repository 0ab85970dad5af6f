"""``plantreg fit-rig``: fit a rig's cameras to landmarks clicked in the recordings themselves.

    plantreg fit-rig --rig START --landmarks LANDMARKS.json --out RIG
                     [--free focal,principal,k1] [--fit CAM,...] [--prior KEY=VAL,...] [--no-snap-depth]
                     [--max-median PX] [--refine] [--silhouette] [--recording DIR ...] [--overwrite] [--quiet]

Writes a normal rig file whose ``"calibration"`` entry is the typed calibration record
(``core/camera/record.py``: method, the landmarks used, every residual, leave-one-out residuals),
and prints the per-camera residual table with the start notes and the worst landmarks (see
docs/fit-rig.md). A fit the landmarks do not support writes nothing and exits 1.
"""

from __future__ import annotations

import argparse
import sys
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
    p.add_argument("--fit", default=None, metavar="CAM,...",
                   help="fit only these cameras (each must have enough landmarks); default: every camera with "
                        "enough landmarks, the others kept at their start pose with a warning")
    p.add_argument("--prior", default="", metavar="KEY=VAL,...",
                   help="prior sigmas around the start rig: rotation (deg, 5), position (m, 0.05), focal "
                        "(relative, 0.05), principal (of the width, 0.03), k1 (0.2), click (px, 1), robust (px, 3); "
                        "e.g. 'focal=0.2' for a focal length from a data sheet")
    from . import nonneg_int, positive_float

    p.add_argument("--max-median", type=positive_float, default=10.0, metavar="PX",
                   help="refuse (write nothing, exit 1) when a camera's median landmark residual exceeds PX "
                        "(default 10)")
    p.add_argument("--no-snap-depth", action="store_true",
                   help="leave out a landmark whose depth lies well behind the surface beside it (the ground "
                        "through a notch, just past a leaf's edge) instead of putting it on that surface (default)")
    p.add_argument("--refine", action="store_true",
                   help="then refine the rig automatically from the images (see docs/fit-rig.md)")
    p.add_argument("--silhouette", action="store_true",
                   help="then fit every camera's pose to the plant outline in all recordings, with the landmarks "
                        "as a term (core/rigfit/silhouette.py; see docs/fit-rig.md)")
    p.add_argument("--recording", action="append", type=Path, default=[], metavar="DIR",
                   help="more recordings for --refine / --silhouette (repeatable)")
    p.add_argument("--worst", type=nonneg_int, default=10, metavar="N", help="worst landmarks to list (default 10)")
    p.add_argument("--overwrite", action="store_true", help="replace RIG if it exists")
    p.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    p.set_defaults(run=run)
    return p


def claim_output_rig(out: Path, overwrite: bool, inputs: list[Path] | None = None):
    """Take an output rig path before any work (``fit-rig``, ``rig create``): the one output
    check and lock (:func:`~..core.io.lock.claim_output`; docs/errors.md, "Paths, names and
    outputs") with the command's ``inputs``, as a context. The rig is then written atomically by
    :meth:`Rig.save`."""
    from ..core.io.lock import claim_output

    return claim_output(out, "output rig", overwrite=overwrite, inputs=list(inputs or []))


def run(args: argparse.Namespace) -> int:
    from .. import cli
    from ..core.data.landmarks import LandmarkSet
    from ..core.camera.rig import Rig
    from ..core.camera.record import landmark_record
    from ..core.data.recording import recording_inputs
    from ..core.rigfit.rigfit import fit_rig_from_file, format_report, keep_not_worse, parse_free, parse_priors

    out: Path = args.out
    if args.recording and not (args.refine or args.silhouette):
        raise InputError("--recording adds recordings for --refine or --silhouette; pass one of them too")
    free = parse_free(args.free)
    priors = parse_priors(args.prior)
    fit_cams = [c.strip() for c in args.fit.split(",") if c.strip()] if args.fit is not None else None
    if fit_cams is not None and not fit_cams:
        raise InputError("--fit names no camera")
    rig = Rig.load(args.rig)
    try:
        rig.depth()
    except InputError as e:
        raise InputError(f"{e.detail}; a landmark fit needs the depth camera", args.rig) from None
    landmarks = LandmarkSet.load(args.landmarks)
    # the output, before the fit: never the start rig, the landmarks or a file of their recordings
    reads = [f for key in landmarks.recordings for f in recording_inputs(landmarks.folder(key))]
    reads += [f for folder in args.recording for f in recording_inputs(folder)]
    with claim_output_rig(out, args.overwrite, [args.rig, args.landmarks, *reads]):  # checked, then locked
        if landmarks.count() > 0:
            result = fit_rig_from_file(rig, landmarks, free=free, priors=priors, cameras=fit_cams,
                                       max_median_px=args.max_median, snap_depth=not args.no_snap_depth)
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
            refined, w = keep_not_worse(fitted, rr.rig, rr.report.get("cameras", {}), "refinement")
            fitted, method = refined, ("landmarks+refine" if report.get("landmarks_used") else "refine")
            report["refine"] = rr.report
            warnings += list(rr.warnings) + w
        if args.silhouette:
            before = fitted
            fitted, method = _silhouette(args, fitted, recordings, by_folder, report, method)
            fitted, w = keep_not_worse(before, fitted, report["silhouette"].get("cameras", {}), "silhouette fit")
            warnings += w
        previous = rig.extra.get("calibration")
        landmark_record(
            method, "plantreg fit-rig", report,
            command="plantreg " + " ".join(getattr(args, "argv", []) or sys.argv[1:]),
            start_rig=str(Path(args.rig).resolve()), landmarks_file=str(Path(args.landmarks).resolve()),
            warnings=warnings,
            **({"previous_method": previous.get("method")} if isinstance(previous, dict) and previous.get("method")
               else {}),
        ).store(fitted)
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
    rig, srep = fit_rig_recordings(fitted, recordings, by_folder, progress=progress,
                                    snap_depth=not args.no_snap_depth)
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
        lines.append(f"  {name:<15} {len(r['views']):>10}  {np.median(med) if med else float('nan'):>17.2f}  {lm}"
                     + ("  REVERTED (worse)" if r.get("reverted") else ""))
    return "\n".join(lines)
