"""The 4K RGB camera as target with the 204-band cube among the sources: `plantreg register`
wall time, peak memory and output size (issue 10: <= 10 s, <= 3 GB, <= 1.5 GB).

    .venv/bin/python benchmarks/bench_4k.py [--data DIR] [--outputs PARTS] [--tiff-codec C]

Rig and recording as in bench_register.py (rendered once into ``--data``, not timed). The
command runs as the only child of this process, so ``ru_maxrss`` of the children is its peak
resident memory. The machine's load average is printed: other processes inflate the wall time.
"""

from __future__ import annotations

import argparse
import compileall
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", type=Path, default=Path(tempfile.gettempdir()) / "plantreg-bench-paper")
    ap.add_argument("--outputs", default=None, help="plantreg register --outputs (default: all)")
    ap.add_argument("--tiff-codec", default=None, help="plantreg register --tiff-codec")
    args = ap.parse_args()
    sys.path.insert(0, str(ROOT / "benchmarks"))
    from bench_register import _prepare  # type: ignore[import-not-found]

    _prepare(args.data)
    # the package's bytecode, as `pip install` writes it: under PYTHONDONTWRITEBYTECODE=1 (set in
    # some development environments) every command would otherwise compile plantreg's modules
    # at start-up again (~0.25 s CPU of a `plantreg register`)
    compileall.compile_dir(str(ROOT / "plantreg_gui"), quiet=1)
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    out = Path(tempfile.mkdtemp(prefix="plantreg-bench-4k-")) / "out"
    cmd = [sys.executable, "-m", "plantreg_gui", "register", "--rig", str(args.data / "rig.json"), "--recording",
           str(args.data / "recording"), "--target", "rgb", "--out", str(out), "--quiet"]
    if args.outputs:
        cmd += ["--outputs", args.outputs]
    if args.tiff_codec:
        cmd += ["--tiff-codec", args.tiff_codec]
    load0 = os.getloadavg()[0]
    t = time.perf_counter()
    subprocess.run(cmd, env=env, check=True, stdout=subprocess.DEVNULL)
    wall = time.perf_counter() - t
    ru = resource.getrusage(resource.RUSAGE_CHILDREN)
    sizes = {str(p.relative_to(out)): p.stat().st_size for p in out.rglob("*") if p.is_file()}
    shutil.rmtree(out.parent, ignore_errors=True)
    print(f"4K RGB target (3840x2160), sources ir, thermal, hyperspectral 512x512x204; "
          f"load average before/after {load0:.1f} / {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    print(f"wall {wall:.1f} s (issue: <= 10 s); CPU {ru.ru_utime + ru.ru_stime:.1f} s")
    print(f"peak resident memory {ru.ru_maxrss / 2**20:.2f} GB (issue: <= 3 GB)")
    print(f"output on disk {sum(sizes.values()) / 2**30:.2f} GB (issue: <= 1.5 GB); largest files: "
          + ", ".join(f"{k} {v / 2**20:.0f} MB" for k, v in sorted(sizes.items(), key=lambda kv: -kv[1])[:4]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
