"""Thermal residuals of a rig (default: the shipped rig.json) on every thermal pair set (fit,
held-out, session 11, the independent s11c set), sorted by depth with each pair's thermal pixel:
is the error a translation (du ~ 1/z), a radial scale (du ~ x r^2) or a constant? Each model is
fitted by least squares to du and dv and judged leave-one-pair-out. Session 12's diagnosis.
  python thermal_depth.py [RIG.json]      (PYTHONPATH = the project root)"""
import sys
from pathlib import Path
import numpy as np
sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[3]))
from eval_s11c import evaluate  # noqa
from plantreg_gui.core.camera.rig import Rig
RES = Path(__file__).resolve().parents[1]
rig_path = sys.argv[1] if len(sys.argv) > 1 else str(RES / "rig.json")
rig = Rig.load(rig_path)
cam = rig.camera("thermal")
K = np.asarray(cam.K)
rows = []
for f in ["landmarks.json", "landmarks_heldout.json", "landmarks_s11.json", "landmarks_independent_s11.json"]:
    for d in evaluate(rig_path, RES / f):
        if d["camera"] != "thermal":
            continue
        d["set"] = f.replace("landmarks", "").replace(".json", "") or "fit"
        from plantreg_gui.core.data.landmarks import LandmarkSet
        ls = LandmarkSet.load(RES / f)
        d["uv"] = list(ls.recordings[d["recording"]][d["index"]].cameras["thermal"])
        rows.append(d)
print(f"{len(rows)} thermal pairs; rig {rig_path}")
keys = list(rows[0].keys())
for d in sorted(rows, key=lambda d: d["z_m"]):
    print(f"  {d['set']:14s} {d['recording'].split('/')[-1]:15s} z {d['z_m']:.3f}  res {d['residual_px']:6.2f}  du {d['du']:+7.2f} dv {d['dv']:+7.2f}"
          f"  uv ({d['uv'][0]:5.1f},{d['uv'][1]:5.1f}) r {np.hypot(d['uv'][0]-319.5, d['uv'][1]-239.5):5.1f}")
z = np.array([d["z_m"] for d in rows]); du = np.array([d["du"] for d in rows]); dv = np.array([d["dv"] for d in rows])
# where the pair is in the thermal image: predicted = read + residual; need read pixel
uv = np.array([d.get("uv_read", d.get("uv", [np.nan, np.nan])) for d in rows], float) if ("uv_read" in keys or "uv" in keys) else None
def loo(X, y):
    e = []
    for i in range(len(y)):
        m = np.ones(len(y), bool); m[i] = False
        c, *_ = np.linalg.lstsq(X[m], y[m], rcond=None)
        e.append(y[i] - X[i] @ c)
    return np.array(e)
one = np.ones_like(z)
models = {"constant": np.c_[one], "translation (1/z)": np.c_[one, 1 / z]}
x = uv[:, 0] - 319.5; y = uv[:, 1] - 239.5; r2 = (x * x + y * y) / 1090.78 ** 2
models["radial k1 (u)"] = np.c_[one, x * r2]
models["translation+radial"] = np.c_[one, 1 / z, x * r2]
for name, X in models.items():
    if X is None:
        continue
    if name.startswith("radial") or name.startswith("translation+"):
        Xv = X.copy(); Xv[:, -1] = y * r2
        eu, ev = loo(X, du), loo(Xv, dv)
    else:
        eu, ev = loo(X, du), loo(X, dv)
    r = np.hypot(eu, ev)
    cu, *_ = np.linalg.lstsq(X, du, rcond=None); cv_, *_ = np.linalg.lstsq(X, dv, rcond=None)
    print(f"{name:20s} LOO median {np.median(r):.2f} px p90 {np.percentile(r, 90):.2f}; coef u {np.round(cu, 2)} v {np.round(cv_, 2)}")
print(f"raw: median {np.median(np.hypot(du, dv)):.2f}")

# is it the depth reading? each landmark moved along its infrared ray (0.4-1.3 m): the best depth and
# how far the read thermal pixel stays off the epipolar line
from plantreg_gui.core.data.landmarks import LandmarkSet  # noqa: E402
from plantreg_gui.core.data.recording import Recording  # noqa: E402

ir, th = rig.depth(), rig.camera("thermal")
print("along the infrared ray:")
for d in sorted(rows, key=lambda d: d["z_m"]):
    ls = LandmarkSet.load(RES / f"landmarks{'' if d['set'] == 'fit' else d['set']}.json")
    lm = ls.recordings[d["recording"]][d["index"]]
    o, ray = ir.rays_rig(np.array([lm.depth_uv], float))
    zs = np.linspace(0.4, 1.3, 901)
    uv_t, _ = th.project(o + zs[:, None] * (ray[0] / ray[0][2]))  # points at infrared depth zs
    e = np.linalg.norm(uv_t - np.asarray(lm.cameras["thermal"]), axis=1)
    j = int(np.nanargmin(e))
    print(f"  {d['set']:14s} {d['recording'].split('/')[-1]:15s} z {d['z_m']:.3f} ({d['residual_px']:5.1f} px)"
          f" -> best z {zs[j]:.3f}: {e[j]:4.1f} px off the epipolar line")
