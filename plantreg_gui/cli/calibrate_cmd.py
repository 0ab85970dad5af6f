"""``plantreg calibrate``: calibrate a rig from a capture session.

    plantreg calibrate SESSION --out RIG --report REPORT
                       [--roi XMIN YMIN ZMIN XMAX YMAX ZMAX] [--exclude POSE:CAM ...]
                       [--detector auto|classic] [--max-rms PX] [--intrinsics CAM=RIG.json ...]
                       [--accept-uncertain] [--overwrite] [--quiet]

Detects the board in every image, calibrates every camera and the rig jointly, computes the
paper's three error tables and writes the rig file (with provenance under ``"calibration"``),
the report JSON and its tables as CSV beside it (``REPORT_STEM_<table>.csv``). Progress on
stderr, a summary on stdout. Session format and tables: ``docs/calibration.md``.

The rig, the report and its CSVs are written as one transaction (all or nothing; the previous
set survives any failure); existing files are replaced only with ``--overwrite``. A calibration
that clearly failed (RMS error above ``--max-rms``, default 2 px) writes nothing and exits 1. So
does one the data do not determine well enough (a camera's projection uncertainty, or a camera's
pose uncertainty relative to the reference, beyond the limits of
:mod:`plantreg_gui.core.calibration.uncertainty`), naming the camera and the parameter, unless
``--accept-uncertain`` (then the rig and the report carry the flag).
"""

from __future__ import annotations

import argparse
import os
import shlex
import sys

import numpy as np

from ..core.errors import InputError


def add_parser(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "calibrate",
        help="calibrate a rig from a capture session (board images of every camera)",
        description="Calibrate all cameras of a rig from a capture session (session.json + one folder per "
        "board pose) and write the rig file, an error report (intrinsic, extrinsic and depth tables) and "
        "the tables as CSV.",
    )
    from . import finite_float, nonempty_path, positive_float

    p.add_argument("session", type=nonempty_path, metavar="SESSION", help="capture session folder (with session.json)")
    p.add_argument("--out", required=True, type=nonempty_path, metavar="RIG", help="rig file to write (JSON)")
    p.add_argument("--report", required=True, type=nonempty_path, metavar="REPORT",
                   help="report JSON to write; the tables go beside it as REPORT_STEM_<table>.csv")
    p.add_argument("--roi", type=finite_float, nargs=6, default=None, metavar=("XMIN", "YMIN", "ZMIN", "XMAX", "YMAX", "ZMAX"),
                   help="region of interest in the rig frame (metres), stored in the rig file and used to mesh "
                        "the session's depth maps for the depth table (default: a box around the board per pose)")
    p.add_argument("--exclude", nargs="+", default=[], metavar="POSE:CAM",
                   help="leave these images out (added to the exclusions stored in the session)")
    p.add_argument("--detector", choices=("auto", "classic"), default="auto",
                   help="chessboard corner detector: 'auto' (findChessboardCornersSB, default) or 'classic' "
                        "(findChessboardCorners + cornerSubPix 11x11, as OpenCV's stereo_calib sample; for comparison)")
    p.add_argument("--max-rms", type=positive_float, default=None, metavar="PX",
                   help="largest RMS reprojection error (px; joint and per camera) a successful calibration may "
                        "have (default 2); above it nothing is written and the exit status is 1")
    p.add_argument("--intrinsics", nargs="+", default=[], metavar="CAM=RIG.json",
                   help="hold camera CAM's intrinsics (K and distortion) at those of the rig file RIG.json (the "
                        "camera of that name, or its only camera) and estimate only the poses; with standard errors "
                        "in the file (a plantreg calibration) they are priors instead of fixed")
    p.add_argument("--accept-uncertain", action="store_true",
                   help="write the rig even when a camera's projection uncertainty or pose uncertainty exceeds the "
                        "documented limits (docs/calibration.md); the rig and the report then carry the flag")
    p.add_argument("--overwrite", action="store_true",
                   help="replace an existing rig file, report and CSV tables (replaced together, only when the new "
                        "set is complete)")
    p.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    p.set_defaults(run=run)
    return p


def _parse_excludes(items: list[str], session) -> set[tuple[str, str]]:
    from ..core.calibration.session import parse_view_key

    out = set()
    poses = {p.name for p in session.poses}
    for it in items:
        try:
            pose, cam = parse_view_key(it)
        except ValueError:
            raise InputError(f"--exclude '{it}': expected POSE:CAMERA, e.g. pose_02:left") from None
        if pose not in poses:
            raise InputError(f"--exclude '{it}': no pose '{pose}' in the session ({', '.join(sorted(poses))})")
        if cam not in session.cameras:
            raise InputError(f"--exclude '{it}': no camera '{cam}' ({', '.join(session.cameras)})")
        out.add((pose, cam))
    return out


def _parse_intrinsics(items: list[str], session) -> dict:
    """``CAM=RIG.json`` items -> camera -> KnownIntrinsics, checked against the session (camera
    exists, image size matches) before any detection."""
    from ..core.calibration.calibrate import check_known_intrinsics, load_known_intrinsics, session_known_intrinsics

    known = session_known_intrinsics(session)
    for it in items:
        cam, sep, path = str(it).partition("=")
        if not sep or not cam or not path:
            raise InputError(f"--intrinsics '{it}': expected CAM=RIG.json, e.g. thermal=thermal_rig.json")
        if cam not in session.cameras:
            raise InputError(f"--intrinsics '{it}': no camera '{cam}' in the session ({', '.join(session.cameras)})")
        known[cam] = load_known_intrinsics(path, cam)
    check_known_intrinsics(session, known)
    return known


def run(args: argparse.Namespace) -> int:
    from .. import cli
    from ..core.calibration import Session
    from ..core.calibration.calibrate import MAX_RMS_PX, quality_problems
    from ..core.calibration.metrics import empty_depth_maps
    from ..core.calibration.report import calibrated_rig, report_files, run_session, write_calibration
    from contextlib import ExitStack

    from ..core.io.lock import claim_output
    from ..core.io.paths import check_output_location
    from ..core.progress import Reporter

    session = Session.load(args.session)
    excluded = session.excluded() | _parse_excludes(args.exclude, session)
    known = _parse_intrinsics(getattr(args, "intrinsics", []), session)
    roi = None
    if args.roi is not None:
        lo, hi = np.array(args.roi[:3]), np.array(args.roi[3:])
        if not np.all(lo < hi):
            raise InputError("--roi: XMIN YMIN ZMIN must be below XMAX YMAX ZMAX")
        roi = (lo, hi)
    # every output, checked before the long work: free (or --overwrite), writable, no input among
    # them, and no two of them the same file (--out X/r_intrinsic.csv --report X/r.json)
    inputs = session.inputs()
    outputs = {args.out.absolute(): "--out"}
    for f in report_files(args.report):
        if f.absolute() in outputs:
            raise InputError(f"--out and --report would write the same file ({f}); choose other names", args.out)
        outputs[f.absolute()] = "--report" if f == args.report else f"--report's table {f.name}"
    for f, what in outputs.items():
        if f != args.report.absolute() and f != args.out.absolute() and os.path.lexists(f):
            check_output_location(f, what, overwrite=args.overwrite, inputs=inputs)
    with ExitStack() as claims:  # rig and report checked and locked, one run at a time (the tables follow the report)
        for f in sorted({args.out.absolute(), args.report.absolute()}):
            claims.enter_context(claim_output(f, outputs[f], overwrite=args.overwrite, inputs=inputs,
                                              lock_what="calibration output"))
        empty, every = empty_depth_maps(session)
        if every and len(empty) == len(every):
            raise InputError(f"none of the session's {len(every)} depth maps has a valid pixel (all 0 or NaN), e.g. "
                             f"{empty[0]}; fix the depth export, or remove \"depth\" from session.json", session.path)

        options = None
        if args.detector != "auto":
            from ..core.calibration import DetectOptions

            stored = session.detect_options()
            options = {}
            for pose in session.poses:
                for cam in session.cameras:
                    o = stored.get((pose.name, cam), DetectOptions())
                    options[(pose.name, cam)] = DetectOptions(o.invert, o.enhance, args.detector)
        progress = Reporter(cli.StderrProgress(quiet=args.quiet))
        detections, cal, report = run_session(session, excluded, options, roi, progress, known=known)
        _print_summary(session, detections, cal, report)
        for w in report.warnings:
            print(f"warning: {w}", file=sys.stderr)
        max_rms = MAX_RMS_PX if args.max_rms is None else args.max_rms
        problems = quality_problems(cal, max_rms, report)
        if problems:
            raise InputError(f"calibration failed, nothing written: {'; '.join(problems)}. Check the board's columns "
                             f"and rows (inner corners: {session.board.columns}x{session.board.rows} now) and square size, "
                             "and the weak views above; --max-rms PX accepts larger errors", session.path)
        uncertain = cal.uncertainty_problems()
        if uncertain and not args.accept_uncertain:
            raise InputError("calibration too uncertain, nothing written: " + "; ".join(uncertain)
                             + ". The data do not determine this; add the views named, or keep it anyway (flagged in "
                               "the rig and the report) with --accept-uncertain", session.path)
        if uncertain:
            cal.accepted_uncertain = list(uncertain)
            report.accepted_uncertain = list(uncertain)
            for u in uncertain:
                print(f"warning: kept with --accept-uncertain: {u}", file=sys.stderr)
        words = getattr(args, "argv", None)
        command = "plantreg " + " ".join(shlex.quote(str(a)) for a in words) if words else None
        rig = calibrated_rig(cal, session, report, roi, command, excluded)
        # everything is computed: now write the rig, the report and its tables as one transaction
        written = write_calibration(rig, args.out, report, args.report)

    if roi is None and rig.depth_camera is not None:
        # a calibration cannot know where the ground is; registration meshes everything above it
        lo, hi = rig.roi_min, rig.roi_max
        print(f"note: no --roi given, so {args.out} has the default region of interest "
              f"x {lo[0]:g}..{hi[0]:g}, y {lo[1]:g}..{hi[1]:g}, z {lo[2]:g}..{hi[2]:g} m with the ground plane "
              f"at z = {hi[2]:g} m; set your rig's with --roi (or the wizard's Save page) before registering",
              file=sys.stderr)
    print(f"wrote {args.out}")
    for p in written:
        if p != args.out:
            print(f"wrote {p}")
    return 0


def _print_summary(session, detections, cal, report) -> None:
    n_found = sum(1 for d in detections.values() if d.found)
    print(f"board found in {n_found} of {sum(1 for d in detections.values() if d.status != 'missing')} images; "
          f"joint RMS {cal.joint_rms_px:.3f} px")
    from ..core.calibration.detect import VARIANT_TEXT, detection_summary
    from ..core.calibration.uncertainty import limits_px

    for cam, c in detection_summary(detections)["cameras"].items():
        how = ", ".join(f"{VARIANT_TEXT.get(v, v)} {n}" for v, n in sorted(c["variants"].items(), key=lambda x: -x[1]))
        print(f"  {cam}: found in {c['found']} of {c['images']} ({100.0 * c['rate']:.1f} %)" + (f"; on: {how}" if how else ""))
    for d in sorted(detections.values(), key=lambda d: d.key):
        if d.status == "failed":
            print(f"  not found: {d.pose}:{d.camera}: {d.reason}")
    print("intrinsics (value +- standard error; mean error px / normalised):")
    for name, c in cal.intrinsics.items():
        e = report.intrinsic.get(name)
        u = cal.uncertainty.get(name)
        sd = u.std if u is not None else {}

        def pm(k, v):
            s_ = sd.get(k, 0.0)
            return f"{k} {v:.2f}" + (f" +- {s_:.2f}" if s_ > 0 else " (fixed)")

        print(f"  {name:14s} {pm('fx', c.K[0, 0])}  {pm('fy', c.K[1, 1])}  {pm('cx', c.K[0, 2])}  {pm('cy', c.K[1, 2])}"
              + (f"   {e['px']:.3f} px / {e['normalized']:.3f}  ({c.n_views} views)" if e else ""))
        lm = c.lens_model_dict()
        print(f"  {'':14s} lens model: {lm.get('label', lm.get('model', '?'))} -- {lm.get('reason', '')}")
        if u is not None:
            med, worst = u.summary()
            lim_med, lim_seen = limits_px(u)
            lo, hi = u.band_m
            at = f"{lo:.2f}-{hi:.2f} m (mrcal, among the boards)" if u.sigma_judged is not None else f"{u.distance_m:.2f} m"
            line = (f"  {'':14s} projection uncertainty at {at}: median {med:.2f} px (limit {lim_med:.2f}), "
                    f"worst where seen {u.covered_worst:.2f} px (limit {lim_seen:.2f}), worst {worst:.2f} px"
                    f" ({', '.join(u.add_views)} {'need more views' if u.needs_views else 'least certain'})")
            if u.rotation_deg is not None:
                line += f"; pose vs {cal.reference}: +- {u.rotation_deg:.3f} deg, +- {u.translation_mm:.2f} mm"
            print(line)
            if u.sigma_boards is not None:
                far = ", ".join(f"{'far' if f >= 100 else f'{f:g}x'} {v:.2f}" for f, v in u.boards_by_distance.items())
                mi = u.summary("intrinsics")[0]
                print(f"  {'':14s} lens model alone (point fixed in the camera) at {u.distance_m:.2f} m: median {mi:.2f} px;"
                      f" among the boards at other distances: {far}")
    if cal.flipped:
        print(f"symmetric board: corner order of {len(cal.flipped)} view(s) turned by 180 degrees to agree with the rig")
    cams = list(session.cameras)
    for title, table in (("extrinsic (epipolar)", report.extrinsic), ("depth", report.depth)):
        if table is None:
            continue
        print(f"{title} error, px (rows: origin, columns: target):")
        print("  " + " " * 14 + "".join(f"{t:>14s}" for t in cams))
        for o in cams:
            cells = []
            for t in cams:
                e = table.get(o, {}).get(t) if o != t else None
                cells.append(f"{e['px']:14.3f}" if e else f"{'-':>14s}")
            print(f"  {o:14s}" + "".join(cells))
    if report.depth_bias:
        vals = np.array([b["bias_mm"] for b in report.depth_bias.values()])
        bad = [p for p, b in report.depth_bias.items() if not b["within_spec"]]
        print(f"ToF bias: median {np.median(vals):.2f} mm, range {vals.min():.2f} .. {vals.max():.2f} mm over "
              f"{len(vals)} poses" + (f"; OUT OF SPEC in {', '.join(bad)}" if bad else " (all within spec)"))
    weak = cal.weak_views
    if weak:
        print("weak views (worst first; not dropped - exclude them with --exclude POSE:CAM if they are bad):")
        for p, c, e, r in weak:
            print(f"  {p}:{c}  {e:.3f} px  {r}")
