"""Session 13 reading views (navigation by each image's own structure; no rig is loaded here).
  python s13_views.py over PLANT OUTDIR          infrared, depth (thermal field region) and the whole thermal image
                                                 turned into the infrared's orientation, labels in original coordinates
  python s13_views.py crop PLANT CAM U V HALF ZOOM OUT.png   one zoomed crop (annotate_view.crop_view), no marks
"""
import sys
from pathlib import Path
import cv2
from annotate_view import crop_view

def _main():
  if sys.argv[1] == "over":
      plant, out = sys.argv[2], Path(sys.argv[3]); out.mkdir(parents=True, exist_ok=True)
      cv2.imwrite(str(out / f"{plant}_ir.png"), crop_view(plant, "ir", 300, 235, 190, 2, tick=20))
      cv2.imwrite(str(out / f"{plant}_depth.png"), crop_view(plant, "depth", 300, 235, 190, 2, tick=20))
      cv2.imwrite(str(out / f"{plant}_thermal.png"), crop_view(plant, "thermal", 320, 240, 330, 1, tick=40))
  else:
      plant, cam, u, v, half, zoom, outp = sys.argv[2:9]
      u, v, half = float(u), float(v), int(half)
      W, H = (640, 480) if cam == "thermal" else (640, 576)
      # the crop is kept inside the image (the per-crop stretch would count padding): centre clamped
      u = min(max(u, half), W - 1 - half); v = min(max(v, half), H - 1 - half)
      cv2.imwrite(outp, crop_view(plant, cam, u, v, half, int(zoom)))


def guess_thermal(u, v):
    """Navigation only (a wide, unmarked thermal crop is centred here): an affine guess from two s11c readings
    of the philodendron (infrared (237, 79) -> thermal (619, 105), (385, 222) -> (355, 423)); no rig."""
    return 619 - (v - 79) * 1.85, 105 + (u - 237) * 2.15


def panel(plant, u, v, outp, half_t=45, zoom_t=5, du=0, dv=0):
    import numpy as np
    from annotate_view import hstack
    tu, tv = guess_thermal(u, v)
    tu, tv = tu + du, tv + dv
    tu = min(max(tu, half_t), 639 - half_t); tv = min(max(tv, half_t), 479 - half_t)
    a = crop_view(plant, "ir", u, v, 16, 9)
    b = crop_view(plant, "depth", u, v, 16, 9)
    c = crop_view(plant, "thermal", tu, tv, half_t, zoom_t)
    cv2.imwrite(outp, hstack([a, b, c]))

if __name__ == "__main__":
    if sys.argv[1] == "panel":
        a = sys.argv[2:]
        panel(a[0], float(a[1]), float(a[2]), a[3], *(int(x) for x in a[4:]))
    else:
        _main()
