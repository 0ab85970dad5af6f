"""Where a batch recording's CPU goes, against the raw Open3D ray-casting budget (issue 10's "batch
<= 3x the ray-casting budget").

    .venv/bin/python benchmarks/bench_budget.py [--data DIR] [--repeat 5]

In one warm process (libraries loaded, as in a batch worker), for the paper-sized recording of
bench_batch.py / bench_register.py (rendered once into ``--data``, not timed), per recording:
CPU time (user + system, all threads) of reading it (``Recording.load``), of registering it
into the infrared view (``Registrar.register``; of which inside Open3D: BVH builds, casts,
occlusion tests) and of writing the default outputs (``write_outputs``) -- best of ``--repeat``.

Printed: the split, the raw Open3D budget in the issue's sense (the same ray casting done with
plain Open3D: ``bench_batch.plain_open3d_budget``), and the floor that reading and writing alone
put on a batch on 2 cores ((read + write CPU) / 2) as a multiple of it (and of the smaller time
plantreg's own run spends inside Open3D): a batch cannot get below it whatever the registration
costs, unless it writes less (``--outputs``) or in a codec Fiji cannot read (``--tiff-codec zstd``).
"""

from __future__ import annotations

import argparse
import os
import resource
import shutil
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", type=Path, default=Path(tempfile.gettempdir()) / "plantreg-bench-paper")
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    sys.path.insert(0, str(ROOT / "benchmarks"))
    sys.path.insert(0, str(ROOT))
    from plantreg_gui import prefer_one_blas_thread

    prefer_one_blas_thread()  # as the CLI and batch workers do
    from bench_batch import open3d_timer, plain_open3d_budget  # type: ignore[import-not-found]
    from bench_register import _prepare  # type: ignore[import-not-found]

    from plantreg_gui.core.export.export import write_outputs
    from plantreg_gui.core.data.recording import Recording
    from plantreg_gui.core.registration.register import Registrar
    from plantreg_gui.core.camera.rig import Rig

    _prepare(args.data)
    rig = Rig.load(args.data / "rig.json")
    work = Path(tempfile.mkdtemp(prefix="plantreg-bench-budget-"))
    rows = []
    try:
        with open3d_timer() as spent:
            for k in range(args.repeat + 1):  # the first round warms up
                c0 = _cpu()
                rec = Recording.load(args.data / "recording", rig)
                c1 = _cpu()
                spent[0] = 0.0
                res = Registrar(rig, rec).register("ir")
                c2 = _cpu()
                o3d = spent[0]
                out = work / f"out{k}"
                write_outputs(res, rig, rec, out)
                c3 = _cpu()
                shutil.rmtree(out)
                if k:
                    rows.append((c1 - c0, c2 - c1, o3d, c3 - c2))
    finally:
        shutil.rmtree(work, ignore_errors=True)
    read, reg, o3d, write = (min(r[i] for r in rows) for i in range(4))
    plain = plain_open3d_budget(args.data, args.repeat)
    cores = 2
    floor = (read + write) / cores
    print(f"paper rig, infrared target; best of {args.repeat} per part; load average {os.getloadavg()[0]:.1f}")
    print(f"  read     {read:5.2f} s CPU")
    print(f"  register {reg:5.2f} s CPU  (inside Open3D: {o3d:.3f} s wall)")
    print(f"  write    {write:5.2f} s CPU  (default outputs)")
    print(f"raw Open3D budget (the issue's 'raw Open3D ray casting of the same work': plain Open3D, every "
          f"target pixel cast, every hit tested towards every source): {plain:.3f} s")
    total = (read + reg + write) / cores
    print(f"  all three: {read + reg + write:5.2f} s CPU -> {total:.2f} s per recording on {cores} cores at best "
          f"(no start-up) = {total / plain:.1f}x the budget ({total / o3d:.1f}x the time inside Open3D)")
    print(f"  reading + writing alone: {floor:.2f} s per recording on {cores} cores = {floor / plain:.1f}x the budget "
          f"({floor / o3d:.1f}x the time inside Open3D)   (issue: batch <= 3x)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
