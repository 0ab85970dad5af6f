"""Session 13: did a camera move between the six recordings? The tray, its frame and the cold spot at the
thermal image's left edge are the same objects in every recording; their image shift between plants
(infrared: phase correlation of a background-only box, sub-pixel) says whether the rig stayed put. The thermal
image has no sharp static structure: the cold spot at its left edge is 0.2-1.7 degC deep, blurred over ~40 px and
touched by leaves on three plants, so its centroid is printed but does not decide anything (phase correlation of that
box gave responses of 0.01-0.14, i.e. no match).
  python s13_static_scene.py     (PYTHONPATH = the project root)"""
import sys
import cv2
import numpy as np
sys.path.insert(0, ".")
from annotate_view import load  # noqa: E402

PL = ["01grapevine", "02leopard_lily", "03areca_palm", "04philodendron", "05boston_fern", "06weeping_fig"]


def shift(cam, box, prep):
    u0, v0, u1, v1 = box
    ref = prep(load(PL[0], cam)[v0:v1, u0:u1])
    win = cv2.createHanningWindow(ref.shape[::-1], cv2.CV_64F)
    for p in PL[1:]:
        a = prep(load(p, cam)[v0:v1, u0:u1])
        (du, dv), resp = cv2.phaseCorrelate(ref, a, win)
        print(f"  {cam:8s} box {box} {p:15s} vs {PL[0]}: shift ({du:+.2f}, {dv:+.2f}) px, response {resp:.2f}")


def ir_prep(a):
    a = np.log1p(a)
    return (a - cv2.GaussianBlur(a, (0, 0), 8)).astype(np.float64)


print("infrared: the tray's frame corners (no leaf in any recording)")
shift("ir", (40, 30, 168, 158), ir_prep)     # top-left tray corner
shift("ir", (440, 30, 568, 158), ir_prep)    # top-right

print("thermal: centroid of the cold spot at the left edge (Gaussian-blurred, pixels colder than the box's "
      "median by more than half the spot's depth)")
for p in PL:
    t = cv2.GaussianBlur(load(p, "thermal"), (0, 0), 2.0)
    box = t[60:150, 0:50]
    med = np.median(box); mn = box.min()
    m = box < med - 0.5 * (med - mn)
    vv, uu = np.nonzero(m)
    w = (med - box)[m]
    print(f"  {p:15s} depth {med - mn:.2f} degC, {m.sum():4d} px, centroid (u {np.sum(uu * w) / w.sum():5.1f}, "
          f"v {60 + np.sum(vv * w) / w.sum():5.1f}), minimum at (u {np.unravel_index(box.argmin(), box.shape)[1]}, "
          f"v {60 + np.unravel_index(box.argmin(), box.shape)[0]})")
