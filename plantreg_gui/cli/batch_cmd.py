"""``plantreg batch``: register many recordings of one rig, locally or on a Dask cluster.

    plantreg batch --rig RIG --target NAME --out OUT [--workers N] [--scheduler ADDRESS]
                   [--overwrite] [--outputs PARTS] [--drop-mixed] [--edge-angle DEG] [--quiet]
                   RECORDING [RECORDING ...]

A RECORDING is a recording folder, or a text/CSV file listing one per line. Each goes to
``OUT/<recording folder name>/`` in ``plantreg register``'s layout; ``OUT/batch.csv`` has one
row per recording (status done / skipped / failed, the error, case shares, timings, files); a
later run into the same OUT adds its rows to it (a recording run again gets its new row). One
plantreg run at a time per OUT (:mod:`plantreg_gui.core.io.lock`: ``.OUT.plantreg-lock`` beside it); a
``--scheduler`` is asked who it is before OUT is created. A re-run skips recordings whose
output is complete and made from the same inputs and parameters. Exit code 1 if any recording failed. Engine: :mod:`plantreg_gui.core.pipeline.batch`
(and :mod:`~plantreg_gui.core.pipeline.batch_guard`).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

from ..core.errors import InputError


#: The most local worker processes ``--workers`` may ask for (more than any workstation's cores;
#: 10**20 was accepted and silently capped).
MAX_WORKERS = 1024


def add_parser(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    from . import nonempty_path
    from .register_cmd import add_output_options, add_registration_options

    p = sub.add_parser(
        "batch",
        help="register many recordings of one rig (local processes or a Dask cluster)",
        description="Register many recordings of one rig into OUT/<recording>/ (plantreg register's layout) "
        "and write OUT/batch.csv. Re-runs skip recordings already done with the same inputs and parameters.",
    )
    p.add_argument("recordings", nargs="+", metavar="RECORDING",
                   help="recording folder, or a text/CSV file listing one recording folder per line")
    p.add_argument("--rig", required=True, type=nonempty_path, metavar="RIG", help="rig file (plantreg.rig JSON)")
    p.add_argument("--target", required=True, metavar="NAME", help="name of the target camera")
    p.add_argument("--out", required=True, type=nonempty_path, metavar="OUT", help="output folder (one sub-folder per recording)")
    p.add_argument("--workers", type=int, default=None, metavar="N",
                   help="local worker processes (default: the number of cores)")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="run on a Dask distributed cluster (e.g. tcp://host:8786) instead of local processes; "
                   "the workers must see the same file system. The scheduler must answer Dask's handshake within "
                   "10 s, checked before OUT is created")
    add_registration_options(p)
    add_output_options(p)
    p.add_argument("--overwrite", action="store_true",
                   help="register every recording again, replacing existing output folders")
    p.add_argument("--quiet", action="store_true", help="no progress on stderr")
    p.set_defaults(run=run)
    return p


class _Progress:
    """Count, rate and ETA on stderr: a tqdm bar on a terminal, plain lines otherwise."""

    def __init__(self, total: int, quiet: bool):
        self.total, self.quiet, self.n, self.t0 = total, quiet, 0, time.monotonic()
        self.bar = None
        if not quiet and sys.stderr.isatty():
            from tqdm import tqdm

            self.bar = tqdm(total=total, unit="rec", file=sys.stderr, dynamic_ncols=True)

    def update(self, row: dict) -> None:
        self.n += 1
        if self.quiet:
            return
        note = f"{row['name']}: {row['status']}" + (f" ({row['error']})" if row.get("error") else "")
        if self.bar is not None:
            self.bar.set_postfix_str(note[:60], refresh=False)
            self.bar.update(1)
            if row["status"] == "failed":
                self.bar.write(f"failed: {note}", file=sys.stderr)
            return
        dt = time.monotonic() - self.t0
        rate = self.n / dt if dt > 0 else 0.0
        eta = (self.total - self.n) / rate if rate > 0 else float("nan")
        print(f"[{self.n}/{self.total}] {note}  {rate:.2f} rec/s, ETA {eta:.0f} s", file=sys.stderr, flush=True)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


def run(args: argparse.Namespace) -> int:
    from ..core.io.lock import claim_output
    from ..core.io.paths import check_output_location
    from ..core.pipeline import batch, batch_guard
    from .register_cmd import load_rig_for_target, output_options, registration_params

    rig_path = args.rig.absolute()
    options = output_options(args)
    load_rig_for_target(rig_path, args.target, options.parts)  # refuses a bad rig before any work
    params = registration_params(args)
    if args.workers is not None and not 1 <= args.workers <= MAX_WORKERS:
        raise InputError(f"--workers must be a whole number from 1 to {MAX_WORKERS}, got {args.workers}")
    out = args.out.absolute()
    jobs = batch.plan(batch.expand_inputs(args.recordings), out)  # name clashes: refused before any work
    # OUT is written into (one folder per recording), never replaced as a whole
    inputs = [rig_path] + [j.recording for j in jobs]
    check_output_location(out, "output", folder=True, into=True, inputs=inputs)  # before the scheduler's handshake
    if args.scheduler:  # before OUT exists: a wrong address leaves nothing behind
        batch_guard.check_scheduler(args.scheduler)
    # checked again and locked: a second run writing OUT meanwhile is refused
    with claim_output(out, "batch output folder", folder=True, into=True, inputs=inputs):
        made = not os.path.lexists(out)
        out.mkdir(parents=True, exist_ok=True)
        try:
            return _run_locked(args, jobs, out, rig_path, options, params)
        finally:
            if made:  # nothing was written (refused, or stopped before the first row): no empty OUT
                try:
                    out.rmdir()
                except OSError:
                    pass


def _run_locked(args, jobs, out: Path, rig_path: Path, options, params) -> int:
    from ..core.errors import one_line, show_path
    from ..core.pipeline import batch, batch_guard

    csv_path = out / batch_guard.BATCH_CSV
    earlier = batch_guard.read_csv(csv_path)  # rows of earlier runs into OUT: kept, ours merged in
    settings = batch.BatchSettings(rig=str(rig_path), target=args.target, out=str(out), params=params.to_dict(),
                                   outputs=options.parts, overwrite=bool(args.overwrite),
                                   tiff_codec=options.tiff_codec, drop_mixed=options.drop_mixed)
    workers = args.workers or os.cpu_count() or 1
    rows_iter = batch.run(settings, jobs, workers, args.scheduler)
    engine = f"Dask scheduler {args.scheduler}" if args.scheduler else f"up to {workers} local worker process(es)"
    if not args.quiet:
        print(f"plantreg batch: {len(jobs)} recording(s) on {engine}", file=sys.stderr, flush=True)

    order = {j.name: i for i, j in enumerate(jobs)}
    rows: dict[str, dict] = {}
    progress = _Progress(len(jobs), args.quiet)

    def table() -> list[dict]:
        return batch_guard.merge_rows(earlier, sorted(rows.values(), key=lambda r: order[r["name"]]))

    t0 = time.monotonic()
    last_csv = 0.0
    try:
        for row in rows_iter:
            rows[row["name"]] = row
            progress.update(row)
            if time.monotonic() - last_csv > 2.0:  # a crash of this process still leaves a table behind
                batch_guard.write_csv(csv_path, table())
                last_csv = time.monotonic()
    finally:
        progress.close()
        if rows:
            batch_guard.write_csv(csv_path, table())
    wall = time.monotonic() - t0
    counts = {s: sum(1 for r in rows.values() if r["status"] == s) for s in ("done", "skipped", "failed")}
    kept = len({r["name"] for r in earlier} - set(rows))
    print(f"{len(jobs)} recording(s): {counts['done']} done, {counts['skipped']} skipped, {counts['failed']} failed "
          f"in {wall:.1f} s; wrote {csv_path}" + (f" (with {kept} row(s) of earlier runs)" if kept else ""))
    for r in sorted(rows.values(), key=lambda r: order[r["name"]]):
        if r["status"] == "failed":
            print(f"  failed {show_path(r['recording'])}: {one_line(r['error'])}")
        elif r.get("warnings"):
            print(f"  warning {show_path(r['recording'])}: {one_line(r['warnings'])}", file=sys.stderr)
    return 1 if counts["failed"] or len(rows) < len(jobs) else 0
