"""Session 13 eye readings (readings_s13.py) -> ../landmarks_s13.json (plantreg.landmarks v1) and
eye_readings_s13.json, by session 11c's protocol (finalize_s11c.py): kept when the two readings agree within 2 px
infrared / 4 px thermal; the mean; the infrared point stepped inward in 0.5 px steps (at most 6) until
check_landmark_depth reads the leaf (status ok), the thermal point by 2.0 px per infrared px along the same
physical direction (thermal turned ~90 deg clockwise: infrared (du, dv) -> thermal (-dv, du)). Every pair is
held out (README "Session 13": none joins a fit of this session).
  python finalize_s13.py     (PYTHONPATH = the project root)"""
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[3])); sys.path.insert(0, str(Path(__file__).resolve().parent))
from plantreg_gui.core.camera.rig import Rig  # noqa: E402
from plantreg_gui.core.data.recording import Recording  # noqa: E402
from plantreg_gui.core.rigfit.rigfit import check_landmark_depth  # noqa: E402
from readings_s13 import R, NAV, REJECTED  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
rig = Rig.load(str(ROOT / "rig_nominal.json"))
out = {"format": "plantreg.landmarks", "version": 1, "recordings": {}}
for key, r in R.items():
    plant, name = key.split("/")
    diffs = {c: float(np.hypot(*np.subtract(r["r1"][c], r["r2"][c]))) for c in ("ir", "thermal")}
    r["diff_px"] = diffs
    if diffs["ir"] > 2.0 or diffs["thermal"] > 4.0:
        r["kept"] = False; r["why"] = "readings disagree"; print(f"{key}: dropped {diffs}"); continue
    ir = np.mean([r["r1"]["ir"], r["r2"]["ir"]], 0); th = np.mean([r["r1"]["thermal"], r["r2"]["thermal"]], 0)
    D = Recording.load(ROOT / "recordings" / plant, rig).depth_m(rig.depth_scale)
    d = np.asarray(r["inward"], float); d /= np.linalg.norm(d)
    dt = np.array([-d[1], d[0]])
    step = 0.0
    while True:
        chk = check_landmark_depth(D, ir + step * d, rig.ground_z)
        if chk.status == "ok" or step >= 6:
            break
        step += 0.5
    if chk.status != "ok":
        r["kept"] = False; r["why"] = f"no leaf depth within 6 px ({chk.status})"; print(key, "dropped: depth"); continue
    uv_ir = ir + step * d; uv_th = th + 2.0 * step * dt
    r.update(kept=True, inward_step_ir_px=step, depth_m=chk.z_m)
    out["recordings"].setdefault(f"recordings/{plant}", {"points": []})["points"].append(
        {"depth_uv": [round(float(x), 2) for x in uv_ir], "cameras": {"thermal": [round(float(x), 2) for x in uv_th]},
         "note": f"s13 {name}: two readings ({diffs['ir']:.1f} / {diffs['thermal']:.1f} px apart), inward {step} px, "
                 f"depth {chk.z_m:.3f} m", "held_out_kind": "independent"})
    print(f"{key}: kept ir {np.round(uv_ir, 2)} thermal {np.round(uv_th, 2)} step {step} z {chk.z_m:.3f} diffs {diffs}")
(ROOT / "landmarks_s13.json").write_text(json.dumps(out, indent=1) + "\n")
(Path(__file__).resolve().parent / "eye_readings_s13.json").write_text(json.dumps(
    {"reader": "s13-thermal", "protocol": __doc__, "navigation": NAV, "looked_at_not_read": REJECTED, "readings": R},
    indent=1) + "\n")
