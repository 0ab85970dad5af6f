"""Figure of the realistic demo's time-of-flight artefacts and their handling (docs/images/tof_demo.png).

    .venv/bin/python figures/tof_demo_figure.py [--seed 0] [--out docs/images/tof_demo.png]

Left: the depth seen from the side (one image row band), as measured (flying pixels red) and
after the clean-up. Right: the thermal image registered into the infrared view, with the
pixels flagged mixed (soil in their footprint) outlined. Not part of the test run.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np


def main() -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from plantreg_gui.core.display.display import to_rgb8
    from plantreg_gui.core.registration.register import filter_depth, register, RegistrationParams
    from plantreg_gui.core.synthetic import demo_rig, make_plant_scene, render_recording
    from plantreg_gui.core.synthetic.demo import THERMAL_BLUR_PX, TOF_DEPTH_NOISE

    ap = argparse.ArgumentParser()
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, default=Path("docs/images/tof_demo.png"))
    args = ap.parse_args()
    rig = demo_rig(thermal_blur_px=THERMAL_BLUR_PX)
    rec = render_recording(rig, make_plant_scene(args.seed), TOF_DEPTH_NOISE, seed=args.seed, tof=True)
    raw = rec.depth_m(rig.depth_scale)
    clean, fly = filter_depth(raw, RegistrationParams())
    res = register(rig, rec, "ir")
    off = register(rig, rec, "ir", RegistrationParams(flying_filter=False, denoise=False, fill_holes=False))

    cam = rig.depth()
    rays = cam.rays_cam(cam.pixel_grid())
    rays = rays / rays[:, 2:3]
    band = np.zeros(cam.shape, bool)
    band[250:330] = True  # a band of rows through the plant

    fig = plt.figure(figsize=(15, 5.4))
    for k, (z, title) in enumerate(((raw, "depth as measured (flying pixels red)"),
                                    (clean, "after the clean-up"))):
        ax = fig.add_subplot(1, 3, k + 1)
        zz = z.reshape(-1)
        ok = np.isfinite(zz) & band.reshape(-1) & (zz < 1.17)
        P = rays[ok] * zz[ok, None]
        f = fly.reshape(-1)[ok] if k == 0 else np.zeros(ok.sum(), bool)
        ax.scatter(P[~f, 0], P[~f, 2], s=0.4, c="0.3", lw=0)
        if f.any():
            ax.scatter(P[f, 0], P[f, 2], s=2, c="red", lw=0)
        ax.set_title(title)
        ax.set_xlabel("x (m)")
        ax.set_ylabel("depth z (m)")
        ax.invert_yaxis()
    ax = fig.add_subplot(1, 3, 3)
    th = to_rgb8(res.registered["thermal"], modality="thermal")
    m = res.mixed["thermal"]
    th[m] = (255, 230, 0)
    ax.imshow(th[120:470, 150:520])
    ax.set_title("registered thermal; yellow: flagged mixed\n(footprint reaches soil, blur 1 px)")
    ax.axis("off")
    fig.suptitle(f"Realistic demo (seed {args.seed}): flying pixels {int(fly.sum())}; "
                 f"thermal P1 pixels flagged mixed {int(m.sum())}; "
                 f"truly occluded -> P2/P3.2 without/with clean-up: see docs/registration.md")
    fig.tight_layout()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.out, dpi=100)
    print(f"wrote {args.out}; off: {off.stats['flying_pixels']} flying")


if __name__ == "__main__":
    main()
