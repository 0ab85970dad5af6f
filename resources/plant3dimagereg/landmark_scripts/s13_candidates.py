"""Session 13: where to look. Convex tips of the infrared plant mask (contour_points, each image's own
silhouette; sigma 2 and 3 px) inside the thermal field's border zones at mid depth, whose outside (5 px along the
outward normal, and 4 px to either side of it) is the ground (> 1.1 m) or no depth: leaf tips against the background, not gaps
between leaves. Only the infrared image and its depth map are used; the thermal field (infrared u 188-411,
v 68-414 at ~0.65 m) and its 50 px border zones are rough figures from the session-11c readings' affine guess
(s13_views.guess_thermal). No rig is loaded.
  python s13_candidates.py     (PYTHONPATH = the project root)"""
import numpy as np
from annotate_view import load
from contour_points import plant_mask, curvature_points

for p in ["01grapevine", "02leopard_lily", "03areca_palm", "04philodendron", "05boston_fern", "06weeping_fig"]:
    m = plant_mask(p, "ir")
    d = load(p, "depth")
    seen, out = [], []
    for sg in (2.0, 3.0):
        P, K, N = curvature_points(m, sg)
        for (u, v), k, n in zip(P, K, N):
            if k <= 0 or not (185 <= u <= 414 and 65 <= v <= 417):
                continue
            if not (u < 238 or u > 361 or v < 118 or v > 364):
                continue
            a = d[int(v) - 2:int(v) + 3, int(u) - 2:int(u) + 3]
            a = a[(a > 0) & (a < 1130)]
            if len(a) < 3:
                continue
            z = np.median(a) / 1000
            t = np.array([-n[1], n[0]])
            outs = []
            for s in (-4, 0, 4):
                q = np.round(np.array([u, v]) - 5 * n + s * t).astype(int)
                dd = d[q[1], q[0]]
                outs.append(dd == 0 or dd > 1100)
            if 0.55 <= z <= 0.9 and all(outs) and not any(np.hypot(u - a_, v - b_) < 4 for a_, b_ in seen):
                seen.append((u, v))
                out.append(f"({u:.0f},{v:.0f}) z{z:.2f} k{k:.2f}")
    print(p, len(out), "; ".join(out))
