"""Registered real grapevine (Plant3DImageReg) before/after the ToF clean-up: the 3D point cloud
coloured by thermal (docs/images/tof_grapevine_thermal_cloud.png).

    xvfb-run -a .venv/bin/python figures/tof_real_registered.py [--plant 01grapevine]

Uses the rig fitted by the annotate work (resources/plant3dimagereg/rig.json; its notes say the
thermal pose is not well determined by its few thermal landmarks). Before: the depth as measured,
every P1 point. After: flying pixels repaired, holes filled, denoised, and P1 points flagged mixed
in the thermal camera left out (its radius includes the rig's median thermal landmark residual).
Also writes docs/images/tof_grapevine_thermal_silhouettes.png: the object mesh's silhouettes
projected into the raw thermal image. Prints the counts. Not part of the test run.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    import pyvista as pv

    from plantreg_gui.core.data.recording import Recording
    from plantreg_gui.core.registration.register import RegistrationParams, register
    from plantreg_gui.core.registration.cases import Case
    from plantreg_gui.core.camera.rig import Rig

    ap = argparse.ArgumentParser()
    ap.add_argument("--plant", default="01grapevine")
    ap.add_argument("--rig", type=Path, default=ROOT / "resources" / "plant3dimagereg" / "rig.json")
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "images" / "tof_grapevine_thermal_cloud.png")
    args = ap.parse_args()
    rig = Rig.load(args.rig)
    rec = Recording.load(ROOT / "resources" / "plant3dimagereg" / "recordings" / args.plant, rig)
    before = register(rig, rec, "ir", RegistrationParams(flying_filter=False, denoise=False, fill_holes=False))
    after = register(rig, rec, "ir")
    clouds = []
    for name, res, drop in (("before", before, False), ("after", after, True)):
        th = np.asarray(res.registered["thermal"])
        sel = (res.cases["thermal"] == Case.P1) & np.isfinite(th)
        n_p1 = int(sel.sum())
        if drop:
            sel &= ~res.mixed["thermal"]
        P = res.points_rig[sel]
        clouds.append((P, th[sel]))
        print(f"{name}: {int(np.count_nonzero(res.flying))} flying pixels; thermal P1 points {n_p1}; "
              f"shown {int(sel.sum())}; flagged mixed {int(np.count_nonzero(res.mixed['thermal']))}")
    lo, hi = np.percentile(np.concatenate([c[1] for c in clouds]), [1, 99.5])
    pl = pv.Plotter(off_screen=True, shape=(1, 2), window_size=(1600, 760), border=False)
    titles = ("as measured: every P1 point (rims of flying pixels)",
              "after: flying pixels repaired, holes filled, denoised, mixed pixels left out")
    for k, (P, T) in enumerate(clouds):
        pl.subplot(0, k)
        cloud = pv.PolyData(P.astype(np.float64))
        cloud["thermal (degC)"] = T
        pl.add_points(cloud, scalars="thermal (degC)", cmap="RdBu_r", clim=(lo, hi), point_size=2.5,
                      render_points_as_spheres=False, show_scalar_bar=(k == 1))
        pl.add_text(titles[k], font_size=10)
        # looking obliquely from the side and above (rig frame: y down, z away from the camera)
        c = np.nanmedian(P, axis=0)
        pl.camera.focal_point = c
        pl.camera.position = c + np.array([0.75, -0.35, -0.35])
        pl.camera.up = (0.0, -1.0, 0.0)
        pl.camera.zoom(1.5)
    pl.link_views()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    pl.screenshot(str(args.out))
    print(f"wrote {args.out}")
    print(f"thermal mixed-flag radius {after.stats['mixed_radius_px']['thermal']:.2f} px "
          "(1 + the rig's median thermal landmark residual)")
    _silhouettes(rig, rec, args.out.with_name("tof_grapevine_thermal_silhouettes.png"))


def _silhouettes(rig, rec, out: Path) -> None:
    """The object mesh's visible silhouettes (what the mixed flag measures from) projected into the
    raw thermal image: where they miss the leaf edges, the rig's thermal pose is off."""
    import cv2

    from plantreg_gui.core.registration.register import Registrar

    reg = Registrar(rig, rec)
    reg.prepare()
    unc = reg.meshes.uncertainty
    top, edges = unc.vertices[: unc.n_vertices // 2], unc.triangles[: unc.n_triangles // 2, :2]
    cam = rig.camera("thermal")
    pv, _z = cam.project(top.astype(np.float64))
    raw = np.asarray(rec.images["thermal"], dtype=np.float64)
    lo, hi = np.percentile(raw, [1, 99.5])
    S = 2
    g = (np.clip((raw - lo) / (hi - lo), 0, 1) * 255).astype(np.uint8)
    im = cv2.cvtColor(cv2.resize(g, None, fx=S, fy=S, interpolation=cv2.INTER_NEAREST), cv2.COLOR_GRAY2BGR)
    ok = np.isfinite(pv[edges]).all(axis=(1, 2))
    ends = np.round((pv[edges[ok]] + 0.5) * S * 8).astype(np.int32)
    cv2.polylines(im, list(ends.reshape(-1, 2, 1, 2)), False, (0, 200, 0), 1, cv2.LINE_AA, 3)
    p = pv[np.unique(edges[ok])]
    p = p[np.isfinite(p).all(axis=1) & cam.in_image(p)]
    c = np.median(p, axis=0)  # the plant's middle; a 400 x 380 px window around it
    (x0, y0), (x1, y1) = c - (200, 190), c + (200, 190)
    x0, y0 = max(0, int(x0)) * S, max(0, int(y0)) * S
    x1, y1 = min(raw.shape[1], int(x1)) * S, min(raw.shape[0], int(y1)) * S
    cv2.imwrite(str(out), im[y0:y1, x0:x1], [cv2.IMWRITE_PNG_COMPRESSION, 9])
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
