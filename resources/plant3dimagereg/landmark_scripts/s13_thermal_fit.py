"""Session 13: the thermal camera refitted alone, with more freedom, judged on pairs it did not see.

The infrared and hyperspectral cameras stay as in ``rig.json``; every landmark's 3D point is the
project's own (``rigfit._collect``: ``check_landmark_depth`` at the infrared pixel, back-projected through
``rig.json``'s infrared lens). The thermal camera is fitted with ``scipy.optimize.least_squares``
(soft-L1 loss at 3 px like ``fit-rig``; priors as ``fit-rig``'s: focal 5 %, principal point 3 % of the
image size, k1/k2 0.2, each prior residual = (value - start) / sigma, i.e. one sigma weighs like one
pixel), starting from ``rig.json``'s thermal pose. Rules (pool, held-out pairs, models, choice, ship
rule): README "Session 13", written before any fit.

  python s13_thermal_fit.py lopo            leave one plant out / one pair out over the pool, every model
  python s13_thermal_fit.py heldout [NEW.json ...]   every model fitted to the pool, on the held-out
                                            independent pairs (s11c + the session-13 files given)
  python s13_thermal_fit.py write MODEL OUT.json     the rig with MODEL's thermal camera fitted to the pool
  python s13_thermal_fit.py timing          per-plant mean and spread of the LOPO residuals (timing hypothesis:
                                            a per-recording offset would show as a large mean, per-leaf motion as spread)
  python s13_thermal_fit.py floor           in-sample floor of the most flexible smooth models (no priors)
  python s13_thermal_fit.py oracle          reader-to-reader floor on the s11c features also read into the pool
(from this folder; PYTHONPATH = the project root)
"""
from __future__ import annotations

import copy
import json
import sys
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares

HERE = Path(__file__).resolve().parent
RES = HERE.parent
sys.path.insert(0, str(RES.parents[1]))
from plantreg_gui.core.camera.rig import Rig  # noqa: E402
from plantreg_gui.core.data.landmarks import LandmarkSet  # noqa: E402
from plantreg_gui.core.data.recording import Recording  # noqa: E402
from plantreg_gui.core.rigfit.rigfit import RecordingLandmarks, _collect  # noqa: E402
import cv2  # noqa: E402

RIG = RES / "rig.json"
POOL_FILES = ["landmarks.json", "landmarks_heldout.json", "landmarks_s11.json"]
EVAL_FILES = ["landmarks_independent_s11.json"]
EXCLUDE = {("01grapevine", (408.5, 396.5))}  # thermal#n2, rejected by every fit (README)
MODELS = {
    "M0": (),
    "M1": ("focal",),
    "M2": ("principal",),
    "M3": ("k1",),
    "M4": ("k1", "k2"),
    "M5": ("focal", "principal", "k1"),
    "M6": ("focal", "principal", "k1", "k2"),
}
ROBUST_PX = 3.0
SIG = {"focal": 0.05 * 1090.78, "cx": 0.03 * 640, "cy": 0.03 * 480, "k1": 0.2, "k2": 0.2}
_DEPTH: dict[str, np.ndarray] = {}


def load_pairs(files, rig: Rig, base: Path = RES) -> list[dict]:
    """Thermal pairs of the landmark files: plant, file, 3D point (rig frame), thermal pixel, depth."""
    out = []
    for f in files:
        p = Path(f) if Path(f).is_absolute() else base / f
        ls = LandmarkSet.load(p, rig)
        for key, pts in ls.recordings.items():
            plant = key.split("/")[-1]
            if plant not in _DEPTH:
                _DEPTH[plant] = Recording.load(ls.folder(key), rig).depth_m(rig.depth_scale)
            rec = RecordingLandmarks(key, _DEPTH[plant], pts)
            duv, z, keys, obs, _rej = _collect(rig, [rec], {"thermal"})
            if len(duv) == 0:
                continue
            dcam = rig.depth()
            xy = dcam.undistort_normalized(duv)
            X = dcam.to_rig(np.concatenate([xy, np.ones((len(xy), 1))], axis=1) * z[:, None])
            for o in obs:
                uv = tuple(round(float(a), 2) for a in o.uv)
                if (plant, tuple(round(a, 1) for a in uv)) in EXCLUDE:
                    continue
                li = keys[o.lm][1]
                out.append({"plant": plant, "file": Path(f).name, "index": li, "note": pts[li].note,
                            "X": X[o.lm], "uv": np.asarray(o.uv, float), "z": float(z[o.lm])})
    return out


class Thermal:
    """Thermal camera parameters: rvec, t, f, cx, cy, k1, k2."""

    def __init__(self, rig: Rig):
        c = rig.camera("thermal")
        self.p0 = np.r_[c.rvec, c.t_cam_rig, c.K[0, 0], c.K[0, 2], c.K[1, 2], 0.0, 0.0]

    @staticmethod
    def project(p, X):
        R = cv2.Rodrigues(p[:3])[0]
        Xc = X @ R.T + p[3:6]
        x, y = Xc[:, 0] / Xc[:, 2], Xc[:, 1] / Xc[:, 2]
        r2 = x * x + y * y
        s = 1 + p[9] * r2 + p[10] * r2 * r2
        return np.c_[p[6] * x * s + p[7], p[6] * y * s + p[8]]


def fit(pairs, free: tuple, p0: np.ndarray) -> np.ndarray:
    X = np.array([d["X"] for d in pairs]); uv = np.array([d["uv"] for d in pairs])
    idx = list(range(6))
    if "focal" in free:
        idx.append(6)
    if "principal" in free:
        idx += [7, 8]
    if "k1" in free:
        idx.append(9)
    if "k2" in free:
        idx.append(10)
    sig = {6: SIG["focal"], 7: SIG["cx"], 8: SIG["cy"], 9: SIG["k1"], 10: SIG["k2"]}

    def res(q):
        p = p0.copy(); p[idx] = q
        r = (Thermal.project(p, X) - uv).ravel()
        pri = [(p[i] - p0[i]) / sig[i] for i in idx if i >= 6]
        return np.r_[r, pri]

    # soft-L1 on the pixel residuals only: priors scaled so the loss stays quadratic for them
    def res_scaled(q):
        r = res(q)
        n = 2 * len(X)
        rp = r[:n] / ROBUST_PX
        rp = np.sign(rp) * np.sqrt(2 * (np.sqrt(1 + rp * rp) - 1)) * ROBUST_PX
        return np.r_[rp, r[n:]]

    sol = least_squares(res_scaled, p0[idx], method="lm" if len(res_scaled(p0[idx])) >= len(idx) else "trf",
                        x_scale="jac")
    p = p0.copy(); p[idx] = sol.x
    return p


def residuals(p, pairs):
    X = np.array([d["X"] for d in pairs]); uv = np.array([d["uv"] for d in pairs])
    return Thermal.project(p, X) - uv


def stats(r):
    e = np.hypot(r[:, 0], r[:, 1])
    return f"median {np.median(e):5.2f} p90 {np.percentile(e, 90):5.2f} max {e.max():5.2f} (n {len(e)})"


def lopo(pool, p0, free):
    """Left-out residuals per pair, in pool order: leave one plant out."""
    out = np.zeros((len(pool), 2))
    for plant in sorted({d["plant"] for d in pool}):
        tr = [d for d in pool if d["plant"] != plant]
        p = fit(tr, free, p0)
        m = [i for i, d in enumerate(pool) if d["plant"] == plant]
        out[m] = residuals(p, [pool[i] for i in m])
    return out


def lopairo(pool, p0, free):
    out = np.zeros((len(pool), 2))
    for i in range(len(pool)):
        p = fit(pool[:i] + pool[i + 1:], free, p0)
        out[i] = residuals(p, [pool[i]])[0]
    return out


def main():
    rig = Rig.load(str(RIG))
    p0 = Thermal(rig).p0
    pool = load_pairs(POOL_FILES, rig)
    cmd = sys.argv[1] if len(sys.argv) > 1 else "lopo"
    if cmd == "lopo":
        print(f"pool: {len(pool)} thermal pairs; " + ", ".join(
            f"{p} {sum(d['plant'] == p for d in pool)}" for p in sorted({d['plant'] for d in pool})))
        print(f"rig.json itself on the pool (fitted to 8 of them): {stats(residuals(p0, pool))}")
        for name, free in MODELS.items():
            rl = lopo(pool, p0, free); rp = lopairo(pool, p0, free)
            pf = fit(pool, free, p0)
            per = " ".join(f"{pl[:6]} {np.median(np.hypot(*rl[[i for i, d in enumerate(pool) if d['plant'] == pl]].T)):.2f}"
                           for pl in sorted({d['plant'] for d in pool}))
            print(f"{name} {'+'.join(free) or 'pose':28s} fitted {stats(residuals(pf, pool))} | LOPO {stats(rl)} [{per}]"
                  f" | LOPairO {stats(rp)}")
            print(f"     f {pf[6]:.1f} c ({pf[7]:.1f}, {pf[8]:.1f}) k1 {pf[9]:+.3f} k2 {pf[10]:+.3f}")
    elif cmd == "heldout":
        ev = load_pairs(EVAL_FILES + [str(Path(a).resolve()) for a in sys.argv[2:]], rig)
        print(f"held out: {len(ev)} thermal pairs")
        print(f"rig.json   {stats(residuals(p0, ev))}  " + " ".join(f"{x:.2f}" for x in np.hypot(*residuals(p0, ev).T)))
        for name, free in MODELS.items():
            pf = fit(pool, free, p0)
            r = residuals(pf, ev)
            print(f"{name} {'+'.join(free) or 'pose':28s} {stats(r)}  " + " ".join(f"{x:.2f}" for x in np.hypot(*r.T)))
        for d, r in zip(ev, residuals(p0, ev)):
            print(f"   {d['file'][:24]:24s} {d['plant']:15s} z {d['z']:.3f} uv ({d['uv'][0]:6.1f},{d['uv'][1]:6.1f}) rig.json du {r[0]:+6.2f} dv {r[1]:+6.2f}")
    elif cmd == "write":
        name, outp = sys.argv[2], sys.argv[3]
        pf = fit(pool, MODELS[name], p0)
        d = json.loads(RIG.read_text())
        for c in d["cameras"]:
            if c["name"] == "thermal":
                c["K"] = [[pf[6], 0, pf[7]], [0, pf[6], pf[8]], [0, 0, 1]]
                c["dist"] = [pf[9], pf[10], 0.0, 0.0, 0.0]
                c["R"] = cv2.Rodrigues(pf[:3])[0].tolist(); c["t"] = pf[3:6].tolist()
        Path(outp).write_text(json.dumps(d, indent=1))
        print(f"wrote {outp}")
    elif cmd == "oracle":
        oracle()
    elif cmd == "floor":
        floor()
    elif cmd == "timing":
        for name in ("M0",):
            rl = lopo(pool, p0, MODELS[name])
            for pl in sorted({d["plant"] for d in pool}):
                m = [i for i, d in enumerate(pool) if d["plant"] == pl]
                print(f"{name} {pl:15s} n {len(m)} mean (du, dv) ({rl[m, 0].mean():+6.2f}, {rl[m, 1].mean():+6.2f}) "
                      f"sd ({rl[m, 0].std():5.2f}, {rl[m, 1].std():5.2f})")



def floor():
    """In-sample floor: the most flexible smooth models fitted to the whole pool by plain least squares
    (no priors, no robust loss). If even these leave residuals far above the reading noise, no camera
    model explains the pairs together (a pair-specific error: leaf motion between captures, reading)."""
    rig = Rig.load(str(RIG))
    p0 = Thermal(rig).p0
    pool = load_pairs(POOL_FILES, rig)
    X = np.array([d["X"] for d in pool]); uv = np.array([d["uv"] for d in pool])
    plants = sorted({d["plant"] for d in pool})
    pid = np.array([plants.index(d["plant"]) for d in pool])

    def model(q, what):
        p = p0.copy(); p[:6] = q[:6]; k = 6
        if "intr" in what:
            p[6:11] = q[6:11]; k = 11
        Xs = X
        if "zscale" in what:  # depth read too long/short by a factor and an offset along each ray
            o = rig.depth().center_rig
            s, off = q[k], q[k + 1]; k += 2
            dvec = X - o; n = np.linalg.norm(dvec, axis=1, keepdims=True)
            Xs = o + dvec * s + dvec / n * off
        pr = Thermal.project(p, Xs)
        if "tang" in what:
            x = (pr[:, 0] - p[7]) / p[6]; y = (pr[:, 1] - p[8]) / p[6]
            p1, p2 = q[k], q[k + 1]; k += 2
            r2 = x * x + y * y
            pr = pr + p[6] * np.c_[2 * p1 * x * y + p2 * (r2 + 2 * x * x), p1 * (r2 + 2 * y * y) + 2 * p2 * x * y]
        if "perplant" in what:
            sh = q[k:k + 2 * len(plants)].reshape(-1, 2); k += 2 * len(plants)
            pr = pr + sh[pid]
        return pr

    for what in ["pose", "pose+intr", "pose+intr+tang", "pose+intr+tang+zscale", "pose+perplant",
                 "pose+intr+perplant"]:
        n = 6 + (5 if "intr" in what else 0) + (2 if "zscale" in what else 0) + (2 if "tang" in what else 0) \
            + (2 * len(plants) if "perplant" in what else 0)
        q0 = np.zeros(n); q0[:6] = p0[:6]
        if "intr" in what:
            q0[6:11] = p0[6:11]
        if "zscale" in what:
            q0[11] = 1.0
        if "perplant" in what:  # one shift per plant is degenerate with the pose: fix the first plant's at 0
            pass
        sol = least_squares(lambda q: (model(q, what) - uv).ravel(), q0, method="trf", x_scale="jac", max_nfev=20000)
        r = model(sol.x, what) - uv
        e = np.hypot(*r.T)
        print(f"{what:26s} params {n:2d} / equations {2 * len(pool)}: in-sample {stats(r)}; worst "
              + ", ".join(f"{pool[i]['plant'][:5]} z{pool[i]['z']:.2f} {e[i]:.1f}" for i in np.argsort(-e)[:4]))



def oracle():
    """Reader-to-reader floor: for each held-out s11c pair whose feature was also read into the pool (infrared
    points within 8 px), the s11c residual of a rig that reproduced the pool's reading exactly: the pool's thermal
    reading moved by rig.json's own image of the small 3D offset between the two infrared points, minus the s11c
    thermal reading. No fit; the size of this is the disagreement between readers, not any camera model's error."""
    rig = Rig.load(str(RIG))
    p0 = Thermal(rig).p0
    pool = load_pairs(POOL_FILES, rig); ev = load_pairs(EVAL_FILES, rig)
    ir = rig.depth()
    out = []
    for e in ev:
        uv_e = ir.project(e["X"][None])[0][0]
        best = None
        for d in pool:
            if d["plant"] != e["plant"]:
                continue
            dist = np.linalg.norm(ir.project(d["X"][None])[0][0] - uv_e)
            if dist < 8 and (best is None or dist < best[0]):
                best = (dist, d)
        if best is None:
            print(f"  {e['plant']:15s} z {e['z']:.3f} thermal ({e['uv'][0]:.1f}, {e['uv'][1]:.1f}): no pool reading of this feature")
            continue
        d = best[1]
        mov = Thermal.project(p0, e["X"][None])[0] - Thermal.project(p0, d["X"][None])[0]
        r = d["uv"] + mov - e["uv"]
        out.append(np.hypot(*r))
        print(f"  {e['plant']:15s} z {e['z']:.3f} thermal ({e['uv'][0]:.1f}, {e['uv'][1]:.1f}) vs pool {d['file']} "
              f"({d['uv'][0]:.1f}, {d['uv'][1]:.1f}), infrared {best[0]:.1f} px apart: a rig exact on the pool reading "
              f"misses s11c by {np.hypot(*r):.2f} px (du {r[0]:+.2f}, dv {r[1]:+.2f})")
    print(f"median over the {len(out)} features read twice: {np.median(out):.2f} px")


if __name__ == "__main__":
    main()
