"""Do leaf edges carry background temperature after registration? (session landmarks, issue 23)

For registrations into the infrared (``plantreg register ... --target ir --out DIR``), the share of
plant pixels in a 2 px band inside the depth-mask outline (``contour_points.plant_mask``) whose
registered thermal value lies nearer the background's (median of the raw thermal frame, which the
background fills) than the leaves' (median of the registered plant pixels 4 px or more inside the
outline); and a picture per registration: registered thermal, the infrared plant outline in green,
cropped to U0 V0 U1 V1 and zoomed.

  cd resources/plant3dimagereg/landmark_scripts && PYTHONPATH=../../.. python edge_temperature.py PLANT OUT.png \\
      U0 V0 U1 V1 ZOOM DIR [DIR ...]
"""

from __future__ import annotations

import sys

import cv2
import numpy as np
import tifffile

from annotate_view import load
from contour_points import plant_mask


def main() -> None:
    plant, out = sys.argv[1], sys.argv[2]
    u0, v0, u1, v1, z = (int(x) for x in sys.argv[3:8])
    m = plant_mask(plant, "ir")
    outline, _ = cv2.findContours(m, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    band = (m > 0) & (cv2.erode(m, np.ones((5, 5), np.uint8)) == 0)
    core = cv2.erode(m, np.ones((9, 9), np.uint8)) > 0
    t_bg = float(np.median(load(plant, "thermal")))
    panels = []
    for d in sys.argv[8:]:
        t = tifffile.imread(f"{d}/registered/thermal.tif").astype(np.float64).squeeze()
        ok = np.isfinite(t)
        t_leaf = float(np.median(t[core & ok]))
        share = float(np.mean(((t - t_bg) / (t_leaf - t_bg))[band & ok] < 0.5))
        print(f"{d}: leaves {t_leaf:.2f} degC, background {t_bg:.2f} degC; edge band nearer the background: "
              f"{100 * share:.1f} % of {int((band & ok).sum())} px")
        lo, hi = np.nanpercentile(t[ok], [2, 98])
        g = np.clip((np.nan_to_num(t, nan=lo) - lo) / (hi - lo) * 255, 0, 255).astype(np.uint8)
        c = cv2.cvtColor(g, cv2.COLOR_GRAY2BGR)
        cv2.drawContours(c, outline, -1, (0, 255, 0), 1)
        c = cv2.resize(c[v0:v1, u0:u1], None, fx=z, fy=z, interpolation=cv2.INTER_NEAREST)
        cv2.putText(c, f"{d}: {100 * share:.1f} %", (4, 16), cv2.FONT_HERSHEY_PLAIN, 1.1, (0, 0, 255), 1)
        panels.append(np.pad(c, ((0, 0), (0, 8), (0, 0)), constant_values=255))
    cv2.imwrite(out, np.concatenate(panels, axis=1))


if __name__ == "__main__":
    main()
