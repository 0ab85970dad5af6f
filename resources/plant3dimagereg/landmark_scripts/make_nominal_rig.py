"""Write ``../rig_nominal.json``: the start rig for ``plantreg fit-rig`` from nominal figures.

Sources (no calibration ships with the data set):

* ``ir`` (Azure Kinect depth/IR, NFOV unbinned, 640 x 576). Intrinsics and lens model are a
  *typical* device, not this one: fx = fy = 504, principal point (323.4, 329.8) = the mean of three
  published NFOV-unbinned calibrations (Azure Kinect SDK factory calibrations quoted in
  microsoft/Azure-Kinect-Sensor-SDK issue #1488, panispani/3DReconstruct calib.md, busybeaver42/kv3),
  converted to the 640 x 576 mode as the SDK does (raw 1024 x 1024 normalised parameters, crop
  offset (192, 180), pixel centres at integer coordinates). Note cy ~ 330, not 288: the NFOV mode
  is cropped off-centre. Distortion: the SDK's rational 6-k Brown-Conrady model = OpenCV's
  rational model [k1, k2, p1, p2, k3, k4, k5, k6]; the k's of the issue-#1488 device (the
  panispani device's k's differ but give the same radial curve within 0.3 px over the image);
  p1 = p2 = 0 (device-specific, ~1e-4). Barrel distortion of ~19 px at 250 px from the centre.
  75 x 65 deg nominal field of view corresponds to ~ fx 417 / fy 452 for an undistorted pinhole;
  with this lens model the corners reach the nominal FOV, so 504 is consistent.
* ``thermal`` (VarioCAM HDx 620, 640 x 480, 32.7 x 24 deg): fx = fy = 320 / tan(32.7/2 deg) = 1090.7
  (square pixels; 24 deg vertical would give 1129: the horizontal figure is taken), principal point
  at the centre, no distortion. Seen rotated ~90 deg clockwise relative to the infrared: the
  infrared's up (-v) is the thermal's right (+u), the infrared's right is the thermal's down.
* ``hyperspectral`` (Specim IQ render, 512 x 512, 31 x 31 deg): fx = fy = 256 / tan(15.5 deg) = 923.1,
  centre, no distortion; rotated ~90 deg anticlockwise: infrared up -> hyperspectral left.
* Translations: a rough placement only, from a coarse silhouette alignment of the grapevine
  (see README): the camera offset (t_z = 0) that makes the plant's centroid (at its median depth) land where the
  silhouettes put it, with the nominal rotation. fit-rig refines them.
* ROI: x in [-0.425, 0.275], y in [-0.525, 0.175], z in [0.30, 1.15] m (rig = depth camera frame).
  The plants stand in a tray: its rim's top at z 1.00-1.07 m, its inner edges at x = -0.435 / +0.284
  and y = -0.536 / +0.186 m; its floor at z 1.18-1.24 m; frames and cables lie around it. x and y
  end 1 cm inside the rim, so the rim, frames and cables drop out while every leaf (all higher than
  the rim, 0.45-0.95 m) stays in; max z = 1.15 keeps the pots and the lowest leaves (areca palm and
  philodendron reach 1.05-1.12 m) and cuts the tray's floor.

  python resources/plant3dimagereg/landmark_scripts/make_nominal_rig.py
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

OUT = Path(__file__).resolve().parents[1] / "rig_nominal.json"

K_IR = [[504.0, 0.0, 323.4], [0.0, 504.0, 329.8], [0.0, 0.0, 1.0]]
DIST_IR = [4.7247, 3.2092, 0.0, 0.0, 0.1706, 5.0559, 4.7758, 0.8865]
F_TH = 320.0 / math.tan(math.radians(32.7 / 2))
F_HS = 256.0 / math.tan(math.radians(31.0 / 2))
# rows = the camera's x (right) and y (down) axes in the rig (infrared) frame
R_TH = [[0, -1, 0], [1, 0, 0], [0, 0, 1]]   # thermal right = infrared up
R_HS = [[0, 1, 0], [-1, 0, 0], [0, 0, 1]]   # hyperspectral right = infrared down
T_TH = [-0.13, 0.03, 0.0]  # rough placement (coarse silhouette alignment of the grapevine, see README)
T_HS = [0.12, -0.01, 0.0]


def main() -> None:
    cams = [
        {"name": "ir", "modality": "infrared", "width": 640, "height": 576, "K": K_IR, "dist": DIST_IR,
         "R": np.eye(3).tolist(), "t": [0.0, 0.0, 0.0], "units": "DN", "bands": [850.0]},
        {"name": "thermal", "modality": "thermal", "width": 640, "height": 480,
         "K": [[round(F_TH, 2), 0.0, 319.5], [0.0, round(F_TH, 2), 239.5], [0.0, 0.0, 1.0]],
         "dist": [0.0, 0.0, 0.0, 0.0, 0.0], "R": R_TH, "t": T_TH, "units": "degC",
         "band_names": ["LWIR 7.5-14 um"]},
        {"name": "hyperspectral", "modality": "hyperspectral", "width": 512, "height": 512,
         "K": [[round(F_HS, 2), 0.0, 255.5], [0.0, round(F_HS, 2), 255.5], [0.0, 0.0, 1.0]],
         "dist": [0.0, 0.0, 0.0, 0.0, 0.0], "R": R_HS, "t": T_HS, "units": "8-bit render",
         "band_names": ["render R", "render G", "render B"], "wavelength_range_nm": [400, 1000]},
    ]
    rig = {"format": "plantreg.rig", "version": 1, "depth": {"camera": "ir", "scale": 0.001},
           "roi": {"min": [-0.425, -0.525, 0.30], "max": [0.275, 0.175, 1.15]}, "cameras": cams,
           "calibration": {"method": "nominal", "source": "resources/plant3dimagereg/landmark_scripts/make_nominal_rig.py "
                           "(datasheet fields of view, typical Azure Kinect NFOV lens, rough placement)"}}
    OUT.write_text(json.dumps(rig, indent=2) + "\n")
    print(OUT)


if __name__ == "__main__":
    main()
