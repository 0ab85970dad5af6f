"""Side-by-side overview of the infrared and another camera (turned to the infrared's orientation)
with every curvature candidate of each image's own silhouette numbered (tips green, notches red),
so that the annotator can pair candidates by eye: "ir 12 = hyperspectral 31".

  python numbered_overview.py PLANT CAM U V HALF_IR ZOOM_IR HALF_OTHER ZOOM_OTHER OUT [U2 V2]
(U, V: infrared centre; U2, V2: the other camera's crop centre, default the image centre)
Writes OUT (PNG) and OUT.json with the candidates (id -> u, v, curvature, inward normal).
"""

from __future__ import annotations

import json
import sys

import cv2
import numpy as np

from annotate_view import crop_view, hstack, load
from contour_points import curvature_points, plant_mask

SCALE = {"ir": 1.0, "hyperspectral": 1.8, "thermal": 2.2}


def annotate(view, cam, plant, u, v, half, zoom, P, K):
    M = 56
    n = 2 * half + 1
    from annotate_view import ROT_TO_IR
    rot = ROT_TO_IR.get(cam, 0)
    V, U = np.mgrid[int(round(v)) - half:int(round(v)) - half + n, int(round(u)) - half:int(round(u)) - half + n]
    U, V = np.rot90(U, rot), np.rot90(V, rot)
    for i, (p, k) in enumerate(zip(P, K)):
        # displayed position of original (p): find the nearest index in the rotated grids
        d = (U - p[0]) ** 2 + (V - p[1]) ** 2
        y, x = np.unravel_index(np.argmin(d), d.shape)
        if d[y, x] > 2:
            continue
        X, Y = int(M + (x + 0.5) * zoom), int(M + (y + 0.5) * zoom)
        c = (0, 200, 0) if k > 0 else (0, 0, 255)
        cv2.circle(view, (X, Y), 3, c, -1)
        cv2.putText(view, str(i), (X + 3, Y - 3), cv2.FONT_HERSHEY_PLAIN, 1.0, (255, 255, 0), 2)
        cv2.putText(view, str(i), (X + 3, Y - 3), cv2.FONT_HERSHEY_PLAIN, 1.0, c, 1)
    return view


def main() -> None:
    a = sys.argv[1:]
    plant, cam = a[0], a[1]
    u, v, hi, zi, ho, zo = float(a[2]), float(a[3]), int(a[4]), int(a[5]), int(a[6]), int(a[7])
    out = a[8]
    img = load(plant, cam)
    u2, v2 = (float(a[9]), float(a[10])) if len(a) > 10 else ((img.shape[1] - 1) / 2, (img.shape[0] - 1) / 2)
    res = {}
    views = []
    for c, cu, cv_, h, z in (("ir", u, v, hi, zi), (cam, u2, v2, ho, zo)):
        P, K, N = curvature_points(plant_mask(plant, c), 2.0 * SCALE[c])
        res[c] = [{"id": i, "uv": [round(float(p[0]), 2), round(float(p[1]), 2)], "k": round(float(k), 3),
                   "n": [round(float(q[0]), 3), round(float(q[1]), 3)]} for i, (p, k, q) in enumerate(zip(P, K, N))]
        view = crop_view(plant, c, cu, cv_, h, z, [], stretch_hs=True, tick=20)
        views.append(annotate(view, c, plant, cu, cv_, h, z, P, K))
    cv2.imwrite(out, hstack(views))
    with open(out + ".json", "w") as f:
        json.dump(res, f)


if __name__ == "__main__":
    main()
