"""Issue 23, session 13: how much of the shipped rig's error on the independent held-out pairs is READING
disagreement? A third reader (s13r, eye_readings_s13r.json, committed before this script was written) read the
other-camera position of the ten features s11c read (landmarks_independent_s11.json).

1. Reader vs reader: per feature, the distance between s13r's mean (r1, r2) and s11c's raw mean (r1, r2) for that
   camera, in the other camera's pixels; median per camera.
2. The pairs as s13r reads them: s11c's infrared point (mean of its r1/r2, = the features' ir_as_read) with s11c's
   inward step (its 'inward' direction, 'inward_step_ir_px'), and s13r's other-camera mean moved by the same physical
   step (2.0 thermal / 1.8 hyperspectral px per infrared px; thermal IR (du, dv) -> (-dv, du), hyperspectral
   -> (dv, -du): finalize_s11c.py's rule, which is a script that rewrites s11c's files when imported, so the rule
   is restated in ``stepped`` and checked here to reproduce landmarks_independent_s11.json from s11c's own
   readings to 0.01 px). Written to ../landmarks_independent_s13r.json and scored with eval_s11c.evaluate (imported).

  cd <project root> && PYTHONPATH=$PWD python resources/plant3dimagereg/landmark_scripts/compare_s13r.py \
      [resources/plant3dimagereg/rig.json]
The same residuals with eval_s11c's own printout:
  cd resources/plant3dimagereg/landmark_scripts && LANDMARKS=../landmarks_independent_s13r.json \
      PYTHONPATH=/work/wt/s13-reader python eval_s11c.py ../rig.json
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
RES = HERE.parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(RES.parents[1]))
import eval_s11c  # noqa: E402

from plantreg_gui.core.data.landmarks import LandmarkSet  # noqa: E402

SCALE = {"thermal": 2.0, "hyperspectral": 1.8}  # other-camera px per infrared px (finalize_s11c.py)
OUT = RES / "landmarks_independent_s13r.json"


def stepped(ir: np.ndarray, other: np.ndarray, cam: str, inward, step: float) -> tuple[np.ndarray, np.ndarray]:
    """finalize_s11c.py's inward step: infrared along the unit 'inward', the other camera along the same
    physical direction, turned as that camera is turned and scaled by SCALE."""
    d = np.asarray(inward, float)
    d = d / np.linalg.norm(d)
    dt = np.array([-d[1], d[0]]) if cam == "thermal" else np.array([d[1], -d[0]])
    return ir + step * d, other + SCALE[cam] * step * dt


def main() -> None:
    rig_path = sys.argv[1] if len(sys.argv) > 1 else str(RES / "rig.json")
    mine = json.loads((HERE / "eye_readings_s13r.json").read_text())["readings"]
    s11c = json.loads((HERE / "eye_readings_s11c.json").read_text())["readings"]
    ref = LandmarkSet.load(RES / "landmarks_independent_s11.json")

    out = {"format": "plantreg.landmarks", "version": 1, "recordings": {}}
    rows = []
    for key, m in mine.items():
        r = s11c[key]
        cam = m["cam"]
        plant, name = key.split("/")
        ir11 = np.mean([r["r1"]["ir"], r["r2"]["ir"]], 0)
        oc11 = np.mean([r["r1"][cam], r["r2"][cam]], 0)
        assert np.allclose(ir11, m["ir_as_read"]), key  # the features file gives s11c's infrared mean
        step = r["inward_step_ir_px"]
        # the restated rule reproduces s11c's own file
        ir_s, oc_s = stepped(ir11, oc11, cam, r["inward"], step)
        (lm,) = [p for p in ref.recordings[f"recordings/{plant}"] if p.note.startswith(f"s11c {name}:")]
        assert np.allclose(lm.depth_uv, ir_s, atol=0.01) and np.allclose(lm.cameras[cam], oc_s, atol=0.01), key
        mean13 = np.asarray(m["mean"], float)
        ir_p, oc_p = stepped(ir11, mean13, cam, r["inward"], step)
        out["recordings"].setdefault(f"recordings/{plant}", {"points": []})["points"].append(
            {"depth_uv": [round(float(x), 3) for x in ir_p], "cameras": {cam: [round(float(x), 3) for x in oc_p]},
             "note": f"s13r {name}: third reader's {cam} mean of two readings ({m['r1_r2_px']:.1f} px apart) with "
                     f"s11c's infrared point and inward step {step} px"})
        rows.append({"key": key, "cam": cam, "step": step, "s13r": mean13, "s11c": oc11,
                     "reader_px": float(np.hypot(*(mean13 - oc11))), "r1r2_s13r": m["r1_r2_px"],
                     "r1r2_s11c": float(np.hypot(*np.subtract(r["r1"][cam], r["r2"][cam])))})
    OUT.write_text(json.dumps(out, indent=1) + "\n")

    res_me = {(d["recording"].split("/")[-1], d["note"].split(":")[0].split(" ", 1)[1]): d
              for d in eval_s11c.evaluate(rig_path, OUT)}
    res_11 = {(d["recording"].split("/")[-1], d["note"].split(":")[0].split(" ", 1)[1]): d
              for d in eval_s11c.evaluate(rig_path, RES / "landmarks_independent_s11.json")}
    print(f"rig {rig_path}; s13r pairs -> {OUT.relative_to(RES.parents[1])}")
    print(f"{'feature':52s} {'cam':5s} {'s13r mean':>16s} {'s11c mean':>16s} {'reader px':>9s} "
          f"{'r1-r2 s13r/s11c':>15s} {'res s13r':>8s} {'res s11c':>8s} {'res mean':>8s}")
    for d in rows:
        plant, name = d["key"].split("/")
        k = (plant, name)
        d["res_s13r"], d["res_s11c"] = res_me[k]["residual_px"], res_11[k]["residual_px"]
        # both readers' pairs share the infrared point (so the rig's prediction): the residual of the two readers'
        # mean point is the mean of their residual vectors
        d["res_both"] = float(np.hypot((res_me[k]["du"] + res_11[k]["du"]) / 2, (res_me[k]["dv"] + res_11[k]["dv"]) / 2))
        print(f"{d['key']:52s} {d['cam'][:5]:5s} ({d['s13r'][0]:6.2f},{d['s13r'][1]:6.2f}) "
              f"({d['s11c'][0]:6.2f},{d['s11c'][1]:6.2f}) {d['reader_px']:9.2f} "
              f"{d['r1r2_s13r']:7.2f}/{d['r1r2_s11c']:5.2f} {d['res_s13r']:8.2f} {d['res_s11c']:8.2f} {d['res_both']:8.2f}")
    for cam in ("thermal", "hyperspectral"):
        c = [d for d in rows if d["cam"] == cam]
        med = lambda f: float(np.median([d[f] for d in c]))  # noqa: E731
        # residual of the mean of the two readers' points (the two readers' pairs share the infrared point)
        print(f"{cam}: n {len(c)}; reader-to-reader median {med('reader_px'):.2f} px (max "
              f"{max(d['reader_px'] for d in c):.2f}); within-reader r1-r2 median s13r {med('r1r2_s13r'):.2f}, "
              f"s11c {med('r1r2_s11c'):.2f}; shipped-rig residual median on s13r's readings {med('res_s13r'):.2f} px, "
              f"on s11c's {med('res_s11c'):.2f} px, on the two readers' mean {med('res_both'):.2f} px")


if __name__ == "__main__":
    main()
