"""Time and accuracy of the automatic rig refinement (issue 8: six recordings < 60 s on 2 cores).

    .venv/bin/python benchmarks/bench_refine.py [--recordings 6]

Renders the demo plants with seeds 101..100+N (and 200 as the unseen plant), disturbs the demo
rig by 3 degrees, 3 cm and 3 % focal length per source camera (fixed seed), refines it from the N
recordings without landmarks (focal length free), and prints wall and CPU seconds and the median /
p90 registration error of the unseen plant against its ground truth per source camera. Rendering
is not timed. Run it on an otherwise idle machine: timings on a loaded one are inflated.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from test_refine import registration_errors  # noqa: E402  (one definition)

from plantreg_gui.core.rigfit.refine import refine_rig  # noqa: E402
from plantreg_gui.core.synthetic import demo_rig, ground_truth, make_plant_scene, render_recording  # noqa: E402
from plantreg_gui.core.synthetic.landmarks import perturb_rig  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--recordings", type=int, default=6)
    a = ap.parse_args()
    truth = demo_rig()
    recs = [render_recording(truth, make_plant_scene(s), seed=s, supersample=1) for s in range(101, 101 + a.recordings)]
    scene = make_plant_scene(200)
    test_rec = render_recording(truth, scene, seed=200, supersample=1)
    gt = ground_truth(truth, scene, "ir")
    start = perturb_rig(truth, np.random.default_rng(7))
    t0, c0 = time.perf_counter(), time.process_time()
    res = refine_rig(start, recs, free=frozenset({"focal"}))
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    print(f"refinement over {a.recordings} recordings: {wall:.1f} s wall, {cpu:.1f} s CPU")
    for name, e in registration_errors(res.rig, test_rec, gt, truth).items():
        entry = res.report["cameras"][name]
        print(f"  {name:14s} unseen plant median {np.median(e):.3f} px  p90 {np.percentile(e, 90):.3f} px  "
              f"converged {entry['converged']}  evaluations {entry['iterations']}  change {entry['change']}")
    for w in res.warnings:
        print("  warning:", w)


if __name__ == "__main__":
    main()
