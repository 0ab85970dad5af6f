"""Flying-pixel filter and denoising on the real Plant3DImageReg depth maps (Azure Kinect, NFOV).

    .venv/bin/python figures/tof_real_data.py [--data ../shared/data/plant3dimagereg]
                                                 [--image docs/images/tof_grapevine_before_after.png]

Prints, per plant, the depth pixels detected as flying and how far denoising moved the others,
and draws the grapevine's point cloud seen from the side before and after (back-projected with
nominal Azure Kinect NFOV intrinsics -- the data set ships no calibration -- so the geometry is
approximate, the flying pixels are not). Not part of the test run.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

PLANTS = ("01grapevine", "02leopard_lily", "03areca_palm", "04philodendron", "05boston_fern", "06weeping_fig")


def main() -> None:
    from plantreg_gui.core.registration.register import RegistrationParams, filter_depth

    ap = argparse.ArgumentParser()
    here = Path(__file__).resolve().parents[2]
    ap.add_argument("--data", type=Path, default=here / "shared" / "data" / "plant3dimagereg")
    ap.add_argument("--image", type=Path, default=None)
    args = ap.parse_args()
    params = RegistrationParams()
    print("plant            valid px   flying px  flying %   of which undecided  denoise: median |dz| mm  p99 mm  time s")
    for name in PLANTS:
        raw = np.load(args.data / "lidar_depthmap_np" / f"{name}.npy").astype(np.float32) * 1e-3
        raw[raw <= 0] = np.nan
        t0 = time.perf_counter()
        clean, fly = filter_depth(raw, params)
        dt = time.perf_counter() - t0
        valid = np.isfinite(raw)
        moved = np.abs(clean - raw)[valid & ~fly & np.isfinite(clean)] * 1e3
        print(f"{name:16s} {valid.sum():9d} {fly.sum():10d} {100 * fly.sum() / valid.sum():8.2f}  "
              f"{int((fly & ~np.isfinite(clean)).sum()):10d}           {np.median(moved):10.2f}          "
              f"{np.percentile(moved, 99):6.2f}  {dt:6.3f}")
        if name == "01grapevine" and args.image is not None:
            _side_view(raw, clean, fly, args.image)


def _side_view(raw: np.ndarray, clean: np.ndarray, fly: np.ndarray, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from plantreg_gui.core.synthetic import demo_rig

    cam = demo_rig().depth()  # nominal Azure Kinect NFOV unbinned intrinsics (640 x 576, f ~ 504 px)
    rays = cam.rays_cam(cam.pixel_grid())  # (N, 3), z = 1
    rays = rays / rays[:, 2:3]

    def cloud(z):
        z = z.reshape(-1)
        ok = np.isfinite(z) & (z < 1.33)  # the plant, not the floor (~1.35-1.4 m)
        return rays[ok] * z[ok, None], ok

    fig, axes = plt.subplots(1, 2, figsize=(12, 5.2), sharex=True, sharey=True)
    P, ok = cloud(raw)
    f = fly.reshape(-1)[ok]
    ax = axes[0]
    ax.scatter(P[~f, 0], P[~f, 2], s=0.3, c="0.35", lw=0)
    ax.scatter(P[f, 0], P[f, 2], s=1.5, c="red", lw=0, label=f"flying pixels ({int(f.sum())})")
    ax.set_title("as measured: flying pixels (red) hang between leaves and floor")
    ax.legend(loc="lower left", markerscale=6)
    Q, _ = cloud(clean)
    ax = axes[1]
    ax.scatter(Q[:, 0], Q[:, 2], s=0.3, c="0.35", lw=0)
    ax.set_title("after plantreg's clean-up (repaired onto their surface, denoised)")
    for a in axes:
        a.set_xlabel("x (m, depth camera frame)")
        a.invert_yaxis()
    axes[0].set_ylabel("depth z (m), camera at the top")
    fig.suptitle("Plant3DImageReg 01grapevine, Azure Kinect depth seen from the side (nominal intrinsics)")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
