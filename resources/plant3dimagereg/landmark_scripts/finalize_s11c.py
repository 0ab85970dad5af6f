"""Eye readings (r1, r2) -> plantreg.landmarks v1 (session s11c, an independent reader; infrared-thermal and a few
infrared-hyperspectral pairs: hyperspectral turned ~90 deg anticlockwise, IR (du, dv) -> (dv, -du), 1.8 px per IR px).
Keep a pair when the readings agree within 2 px infrared / 4 px thermal; the pair is the mean. Its infrared point
must read the leaf (check_landmark_depth with the nominal rig: status ok): else it is stepped inward along the
given leaf direction in 0.5 px steps (at most 6 px) until it does, and the thermal point by 2 px per infrared px
along the same physical direction (thermal is turned ~90 deg clockwise: IR (du, dv) -> thermal (-dv, du))."""
import json, sys, math
import numpy as np
from pathlib import Path; sys.path.insert(0, str(Path(__file__).resolve().parents[3])); sys.path.insert(0, str(Path(__file__).resolve().parent))
from plantreg_gui.core.camera.rig import Rig
from plantreg_gui.core.data.recording import Recording
from plantreg_gui.core.rigfit.rigfit import check_landmark_depth
from readings_s11c import R, NAV, REJECTED
ROOT = str(Path(__file__).resolve().parents[1]) + '/'
rig = Rig.load(ROOT + 'rig_nominal.json')
TOL = {"ir": 2.0, "thermal": 4.0, "hyperspectral": 4.0}
SCALE = {"thermal": 2.0, "hyperspectral": 1.8}
out = {"format": "plantreg.landmarks", "version": 1, "recordings": {}}
raw = {}
for key, r in R.items():
    plant, name = key.split('/')
    raw[key] = r
    oc = r.get("cam", "thermal"); cams = ["ir", oc]
    ok, diffs = True, {}
    for c in cams:
        if r.get("r2", {}).get(c) is None or r["r1"].get(c) is None:
            ok = False; diffs[c] = None; continue
        diffs[c] = float(np.hypot(*np.subtract(r["r1"][c], r["r2"][c])))
        ok &= diffs[c] <= TOL[c]
    r["diff_px"] = diffs
    if r.get("drop"):
        ok = False
    if not ok:
        r["kept"] = False; r["why"] = r["drop"] if r.get("drop") else "readings disagree" if all(d is not None for d in diffs.values()) else "second reading not possible"
        print(f"{key:55s} dropped {diffs}"); continue
    ir = np.mean([r["r1"]["ir"], r["r2"]["ir"]], 0); th = np.mean([r["r1"][oc], r["r2"][oc]], 0)
    D = Recording.load(ROOT + 'recordings/' + plant, rig).depth_m(rig.depth_scale)
    d = np.asarray(r["inward"], float); d /= np.linalg.norm(d)
    dt = np.array([-d[1], d[0]]) if oc == "thermal" else np.array([d[1], -d[0]])
    step = 0.0
    while True:
        chk = check_landmark_depth(D, ir + step * d, rig.ground_z)
        if chk.status == "ok" or step >= 6:
            break
        step += 0.5
    if chk.status != "ok":
        r["kept"] = False; r["why"] = f"no leaf depth within 6 px inward ({chk.status})"; print(key, 'dropped depth'); continue
    uv_ir = ir + step * d; uv_th = th + SCALE[oc] * step * dt
    r["kept"] = True; r["inward_step_ir_px"] = step; r["depth_m"] = chk.z_m
    rec = out["recordings"].setdefault(f"recordings/{plant}", {"points": []})
    rec["points"].append({"depth_uv": [round(float(x), 2) for x in uv_ir], "cameras": {oc: [round(float(x), 2) for x in uv_th]},
                          "note": f"s11c {name}: independent reader, two readings ({diffs['ir']:.1f} / {diffs[oc]:.1f} px apart), inward {step} px, depth {chk.z_m:.3f} m"})
    print(f"{key:55s} kept ir {np.round(uv_ir,2)} th {np.round(uv_th,2)} step {step} z {chk.z_m:.3f} diffs {diffs}")
json.dump(out, open(ROOT + 'landmarks_independent_s11.json', 'w'), indent=1)
json.dump({"reader": "s11-h23c", "protocol": __doc__, "navigation": NAV, "looked_at_not_read": REJECTED, "readings": raw},
          open(ROOT + 'landmark_scripts/eye_readings_s11c.json', 'w'), indent=1)
