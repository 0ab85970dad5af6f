"""Session 13: was the thermal image resampled (scaled/rotated) by the data set's authors? A native
640 x 480 microbolometer frame has no padding at its corners and nearly uncorrelated pixel noise;
an interpolated (rotated, rescaled) frame has filled corners or a constant border and neighbour
noise correlation well above zero in both axes (bilinear: ~0.5 and more). Measured on a high-pass of
each thermal image (value minus its 5x5 median), in the background-only corner boxes.
  python s13_resample_check.py     (PYTHONPATH = the project root)"""
import sys
import cv2
import numpy as np
sys.path.insert(0, ".")
from annotate_view import load  # noqa: E402

for p in ["01grapevine", "02leopard_lily", "03areca_palm", "04philodendron", "05boston_fern", "06weeping_fig"]:
    t = load(p, "thermal")
    hp = t - cv2.medianBlur(t.astype(np.float32), 5).astype(np.float64)
    out = []
    for (v0, v1, u0, u1) in [(0, 60, 560, 640), (420, 480, 560, 640), (0, 60, 0, 80), (420, 480, 0, 80)]:
        a = hp[v0:v1, u0:u1]; a = a - a.mean()
        cu = np.mean(a[:, 1:] * a[:, :-1]) / a.var(); cv_ = np.mean(a[1:] * a[:-1]) / a.var()
        cd = np.mean(a[1:, 1:] * a[:-1, :-1]) / a.var()
        out.append(f"({cu:+.2f},{cv_:+.2f},{cd:+.2f})")
    edge = [t[0, :].std(), t[-1, :].std(), t[:, 0].std(), t[:, -1].std()]
    print(f"{p:15s} {t.shape} corners {t[0,0]:.2f} {t[0,-1]:.2f} {t[-1,0]:.2f} {t[-1,-1]:.2f}; border-row std "
          + " ".join(f"{e:.3f}" for e in edge) + "; lag-1 noise corr (u, v, diag) per corner box " + " ".join(out))
