"""Residuals of a rig on the s11c independent pairs (``../landmarks_independent_s11.json``, or LANDMARKS=FILE):
per pair (predicted minus read, px, in the camera's own pixel axes; depth used), per camera and plant, and
per camera median / p90 (numpy's linear percentile). The rig is only evaluated, never fitted.
  python eval_s11c.py RIG.json [RIG2.json ...]      (from this folder; PYTHONPATH = the project root)
"""
from __future__ import annotations

import os
import sys
from pathlib import Path

import numpy as np

RES = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(RES.parents[1]))
from plantreg_gui.core.camera.rig import Rig  # noqa: E402
from plantreg_gui.core.data.landmarks import LandmarkSet  # noqa: E402
from plantreg_gui.core.data.recording import Recording  # noqa: E402
from plantreg_gui.core.rigfit.rigfit import RecordingLandmarks, check_landmark_depth, evaluate_landmarks  # noqa: E402


def evaluate(rig_path: str, lm_path: Path) -> list[dict]:
    rig = Rig.load(rig_path)
    ls = LandmarkSet.load(lm_path, rig)
    recs = []
    for key, pts in ls.recordings.items():
        D = Recording.load(ls.folder(key), rig).depth_m(rig.depth_scale)
        recs.append(RecordingLandmarks(key, D, pts))
    rows, rejected = evaluate_landmarks(rig, recs)
    if rejected:
        raise SystemExit(f"{lm_path}: landmarks without depth: {rejected}")
    depth = {r.name: r.depth_m for r in recs}
    for d in rows:
        lm = ls.recordings[d["recording"]][d["index"]]
        d["z_m"] = check_landmark_depth(depth[d["recording"]], lm.depth_uv, rig.ground_z).z_m
    return rows


def main() -> None:
    lm_path = Path(os.environ.get("LANDMARKS", RES / "landmarks_independent_s11.json"))
    for rig_path in sys.argv[1:]:
        rows = evaluate(rig_path, lm_path)
        print(f"== {rig_path} on {lm_path.name}")
        for d in sorted(rows, key=lambda d: (d["camera"], d["recording"], d["index"])):
            print(f"  {d['camera']:13s} {d['recording'].split('/')[-1]:15s} z {d['z_m']:.3f} m  {d['residual_px']:6.2f} px "
                  f"(du {d['du']:+6.2f}, dv {d['dv']:+6.2f})  {d['note'].split(':')[0][5:]}")
        for cam in sorted({d["camera"] for d in rows}):
            r = [d for d in rows if d["camera"] == cam]
            v = np.array([d["residual_px"] for d in r])
            per = ", ".join(f"{p.split('/')[-1]} {np.median([d['residual_px'] for d in r if d['recording'] == p]):.2f} "
                            f"(n {sum(d['recording'] == p for d in r)})" for p in sorted({d['recording'] for d in r}))
            print(f"  {cam}: n {len(v)}, median {np.median(v):.2f} px, p90 {np.percentile(v, 90):.2f}, max {v.max():.2f}, "
                  f"mean du {np.mean([d['du'] for d in r]):+.2f} dv {np.mean([d['dv'] for d in r]):+.2f}; per plant: {per}")


if __name__ == "__main__":
    main()
