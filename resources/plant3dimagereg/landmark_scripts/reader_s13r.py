"""Session 13, issue 23: views for a THIRD independent reader (s13r) of ten features already read by s11c.

The reader looks only at the images, the depth map and the NOMINAL rig (rig_nominal.json, ~10-20 px
off) for rough centring; no fitted rig and no earlier reader's positions in the other camera.

Views (all PNGs, crops turned to the infrared's orientation by annotate_view.crop_view, axis labels
naming the original coordinate):

  ctx   <feature> -o DIR        infrared / depth / other-camera context crops (zoom 3-4) around the
                                infrared point and its nominal-rig projection
  crop  <feature> U V -o P      the other camera, zoomed crop centred at (U, V) (``--half``, ``--zoom``,
                                ``--mark`` for candidate points), thermal in a FIXED degree-C window

Thermal window: the plant's 2-98 percentile of the whole thermal image (fixed per plant, not per
crop), unless ``--tlo/--thi`` are given. CLAHE is not applied to it (so a grey level is a temperature).

  PYTHONPATH=$PWD python resources/plant3dimagereg/landmark_scripts/reader_s13r.py ctx 02leopard_lily/top_leaf_tip -o /tmp/r
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import cv2
import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
import annotate_view as av  # noqa: E402

from plantreg_gui.core.camera.rig import Rig  # noqa: E402

FEATURES = Path("/work/wt/s13_reader_features.json")
NOMINAL = HERE.parent / "rig_nominal.json"
_WINDOW: dict[str, tuple[float, float]] = {}


def feature(key: str) -> dict:
    f = json.loads(FEATURES.read_text())[key]
    plant = key.split("/")[0]
    return {"plant": plant, "cam": f["cam"], "ir": tuple(f["ir_as_read"]), "name": key.split("/")[1]}


def nominal_projection(plant: str, cam: str, u: float, v: float, r: int = 2) -> tuple[np.ndarray, float]:
    """Infrared pixel -> other camera through the nominal rig, depth = median valid depth within r px."""
    rig = Rig.load(NOMINAL)
    depth = np.load(av.DATA / "lidar_depthmap_np" / f"{plant}.npy").astype(np.float64)
    iu, iv = int(round(u)), int(round(v))
    w = depth[iv - r:iv + r + 1, iu - r:iu + r + 1]
    z = float(np.median(w[w > 0])) * rig.depth_scale if (w > 0).any() else 0.7
    ir = rig.camera("ir")
    ray = ir.rays_cam(np.array([[u, v]]))[0]
    X = ray * z  # z = 1 rays, so this is the point at depth z
    uv, _ = rig.camera(cam).project(X[None])
    return uv[0], z


def fixed_thermal_stretch(plant: str, lo: float | None, hi: float | None, blur: float = 0.0):
    """Patch annotate_view so that thermal crops use one fixed degree-C window (and, with ``blur``,
    a Gaussian of that sigma in thermal pixels for display: low-contrast leaves in sensor noise)."""
    t = av.load(plant, "thermal")
    if lo is None or hi is None:
        lo, hi = np.percentile(t[np.isfinite(t)], [2, 98])
    _WINDOW["thermal"] = (float(lo), float(hi))
    orig = av.stretch

    def stretch(cam, a, stretch_hs=False):
        if cam != "thermal":
            return orig(cam, a, stretch_hs)
        lo_, hi_ = _WINDOW["thermal"]
        g = np.clip((a - lo_) / (hi_ - lo_) * 255, 0, 255).astype(np.uint8)
        return cv2.cvtColor(g, cv2.COLOR_GRAY2BGR)

    av.stretch = stretch  # crop_view looks the name up at call time
    if blur > 0:
        orig_load = av.load

        def load(plant_, cam_):
            a = orig_load(plant_, cam_)
            return cv2.GaussianBlur(a, (0, 0), blur) if cam_ == "thermal" else a

        av.load = load
    return lo, hi


def main(argv=None) -> None:
    p = argparse.ArgumentParser()
    p.add_argument("what", choices=["ctx", "crop", "ircrop"])
    p.add_argument("feature")
    p.add_argument("uv", nargs="*", type=float)
    p.add_argument("-o", "--out", required=True)
    p.add_argument("--half", type=int, default=15)
    p.add_argument("--zoom", type=int, default=12)
    p.add_argument("--mark", action="append", default=[])
    p.add_argument("--tlo", type=float)
    p.add_argument("--thi", type=float)
    p.add_argument("--hs-stretch", action="store_true")
    p.add_argument("--blur", type=float, default=0.0, help="thermal display blur sigma (px)")
    a = p.parse_args(argv)
    f = feature(a.feature)
    plant, cam = f["plant"], f["cam"]
    lo, hi = fixed_thermal_stretch(plant, a.tlo, a.thi, a.blur)
    marks = [tuple(float(x) for x in m.split(",")) for m in a.mark]
    if a.what == "ctx":
        out = Path(a.out)
        out.mkdir(parents=True, exist_ok=True)
        u, v = f["ir"]
        nom, z = nominal_projection(plant, cam, u, v)
        print(f"{a.feature}: ir ({u}, {v}) depth {z:.3f} m -> nominal {cam} ({nom[0]:.1f}, {nom[1]:.1f});"
              f" thermal window {lo:.2f}..{hi:.2f} C")
        tag = a.feature.replace("/", "_").replace("#", "_")
        views = [av.crop_view(plant, "ir", u, v, half=40, zoom=4, marks=[(u, v)], tick=10),
                 av.crop_view(plant, "depth", u, v, half=40, zoom=4, marks=[(u, v)], tick=10)]
        cv2.imwrite(str(out / f"{tag}_ir_ctx.png"), av.hstack(views))
        halfo = 60 if cam == "thermal" else 45
        cv2.imwrite(str(out / f"{tag}_{cam}_ctx.png"),
                    av.crop_view(plant, cam, nom[0], nom[1], half=halfo, zoom=3 if cam == "thermal" else 4,
                                 marks=[tuple(nom)] + marks, tick=10, stretch_hs=a.hs_stretch))
        cv2.imwrite(str(out / f"{tag}_ir_zoom.png"),
                    av.crop_view(plant, "ir", u, v, half=12, zoom=16, marks=[(u, v)]))
        return
    u, v = a.uv
    c = "ir" if a.what == "ircrop" else cam
    img = av.crop_view(plant, c, u, v, half=a.half, zoom=a.zoom, marks=marks, stretch_hs=a.hs_stretch,
                       tick=5 if a.zoom >= 7 else 10)
    cv2.imwrite(a.out, img)


if __name__ == "__main__":
    main()
