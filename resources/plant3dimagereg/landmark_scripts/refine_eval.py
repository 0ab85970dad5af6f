"""Image-based refinement on the real plants, judged by landmarks it did not use (session land13).

Run from this folder with ``PYTHONPATH=../../..``. Subcommands:

``scan CAM PLANT|all VARIANT [OUT.png]``
    The refinement's cost (``core/rigfit/refine.py``'s NID at its finest level, the points and weights
    it uses) along 1-D scans of each pose parameter around ``rig.json``'s pose, with the
    landmark median at each step; the minimum of the cost against the landmark pose (0).
``lopo CAM VARIANT MODE``
    Hyperspectral leave-one-plant-out: per annotated plant, start = the landmark fit
    (``--free ir:k1``, from ``rig_nominal.json``) without that plant's landmarks, then the
    refinement (``MODE`` joint: the six plants' images; perplant: that plant's image only), and
    that plant's landmarks measured (never used by the fit nor by the refinement).
``heldout CAM VARIANT MODE``
    From ``rig.json``: refine, then the residuals on ``landmarks_heldout.json`` (thermal: the 5
    pairs of session land12 ``rig.json`` never saw; ``thermal_eval.heldout_landmarks``: env
    HELD_OUT_KIND=independent for the 2 of session landmarks) and on ``landmarks.json`` (fitted, not independent).

VARIANT: comma-separated items
    ``nid`` (default objective), ``roi`` (only points inside the rig's ROI: the plant; no ground),
    ``pca1`` / ``pca2`` / ``pca3`` (hyperspectral: the data set's ``hs_pca_01`` principal-component
    render, channel k, instead of the RGB render's first principal component), ``exg`` (2G - R - B of
    the RGB render: vegetation against soil), ``grad`` (NID of the gradient magnitudes of the blurred
images: edges), ``depthref`` (the depth map as the reference instead of the infrared image), ``fine`` (only the two finest levels: 0.2 deg and
    0.8 px; a small correction near the start), ``rot`` (rotation only: image shift and roll, every level),
``shift`` (image shift only), ``lmW`` (landmarks + image: W * mean log(1 + r^2 / 9) of the landmarks
the start rig was fitted to added to the NID; in ``lopo`` the other plants' landmarks only).
"""

from __future__ import annotations

import copy
import sys
import time
from pathlib import Path

import cv2
import numpy as np

import plantreg_gui.core.rigfit.refine as R
from plantreg_gui.core.data.recording import Recording
from plantreg_gui.core.camera.rig import Rig
from plantreg_gui.core.rigfit.rigfit import evaluate_landmarks

from thermal_eval import RES, fit, heldout_landmarks, load, only

DATA = (RES / "../../../shared/data/plant3dimagereg").resolve()
PLANTS = ["01grapevine", "02leopard_lily", "03areca_palm", "04philodendron", "05boston_fern", "06weeping_fig"]


def recordings(rig: Rig, variant: set[str], plants=PLANTS) -> list[Recording]:
    recs = []
    for p in plants:
        rec = Recording.load(RES / "recordings" / p, rig)
        for k in (1, 2, 3):
            if f"pca{k}" in variant:  # cv2 reads BGR: PC1 is the PNG's red channel
                rec.images["hyperspectral"] = cv2.imread(str(DATA / "hs_pca_01" / f"{p}.png"))[:, :, 3 - k]
        if "depthref" in variant:  # the refinement then takes the depth map itself as the reference
            rec.images.pop("ir", None)
        if "exg" in variant:
            a = rec.images["hyperspectral"].astype(np.float32)
            rec.images["hyperspectral"] = 2 * a[:, :, 1] - a[:, :, 0] - a[:, :, 2]
        recs.append(rec)
    return recs


def _grad_blur(img: np.ndarray, sigma: float) -> np.ndarray:
    """Gradient magnitude of the blurred image (both the reference and the source): edges only."""
    b = R._blur(img, max(sigma, 0.8))
    gx = cv2.Sobel(b, cv2.CV_32F, 1, 0, ksize=3)
    gy = cv2.Sobel(b, cv2.CV_32F, 0, 1, ksize=3)
    return np.sqrt(gx * gx + gy * gy)


def _plant_points_only(X: np.ndarray, roi, weight: np.ndarray) -> np.ndarray:
    obj = np.all((X >= roi[0]) & (X <= roi[1]), axis=1)
    return np.where(obj, weight, 0.0)


def apply_variant(p: R.RefineParams, variant: set[str]) -> R.RefineParams:
    """The variant through the refinement's experiment hooks (``RefineParams``): ``grad`` compares
    gradient magnitudes, ``rot`` / ``shift`` search a rotation / an image shift only at every
    level, ``roi`` weights the plant's points only."""
    p.image_filter = _grad_blur if "grad" in variant else None
    if "rot" in variant:  # a rotation only (image shift and roll) at every level
        p.active_params = lambda level, n, focal: [0, 1, 2]
    elif "shift" in variant:  # an image shift only
        p.active_params = lambda level, n, focal: [0, 1]
    p.point_weights = _plant_points_only if "roi" in variant else None
    return p


def landmark_cost(rig: Rig, lm, cam: str, variant: set[str]):
    """``lmW``: W * mean(log(1 + r^2 / 3^2)) of the landmarks ``lm`` (r px, Cauchy at 3 px, the
    reading uncertainty), added to the NID: landmarks and image in one objective (None without lmW)."""
    from plantreg_gui.core.rigfit.rigfit import _collect

    w = [float(x[2:]) for x in variant if x.startswith("lm") and x[2:].replace(".", "").isdigit()]
    if not w:
        return None
    duv, z, keys, obs, _ = _collect(rig, only(lm, cam), {cam})
    dcam = rig.depth()
    xy = dcam.undistort_normalized(duv)
    X = dcam.to_rig(np.concatenate([xy, np.ones((len(xy), 1))], axis=1) * z[:, None])
    Xl, uvl, weight = np.array([X[o.lm] for o in obs]), np.array([o.uv for o in obs]), w[0]

    def cost(camera) -> float:
        uv, _ = camera.project(Xl)
        r2 = np.sum((uv - uvl) ** 2, axis=1)
        return weight * float(np.mean(np.log1p(r2 / 9.0)))
    return cost


def params(variant: set[str], extra_cost=None) -> R.RefineParams:
    p = apply_variant(R.RefineParams(keep_if_landmarks_disagree=False, workers=1), variant)
    p.extra_cost = extra_cost
    if "fine" in variant:
        p.levels_deg = (0.2, 0.0)
    if any(x.startswith("lm") for x in variant):
        # the convergence tests compare the cost with the landmark term against a chance NID
        # without it: meaningless here (the held-out landmarks judge)
        p.min_information = p.min_contrast = -1e9
    return p


def judge(rig: Rig, lm, cam: str) -> dict[str, list[float]]:
    rows, _ = evaluate_landmarks(rig, only(lm, cam))
    out: dict[str, list[float]] = {}
    for d in rows:
        out.setdefault(d["recording"].split("/")[-1], []).append(d["residual_px"])
    return out


def fmt(per: dict[str, list[float]]) -> str:
    allv = [x for v in per.values() for x in v]
    if not allv:
        return "-"
    return (f"median {np.median(allv):5.2f} p90 {np.percentile(allv, 90):5.2f} (n {len(allv)}) | "
            + " ".join(f"{k[:6]} {np.median(v):.2f}" for k, v in sorted(per.items())))


def refine(rig: Rig, recs: list[Recording], cam: str, variant: set[str], extra_cost=None) -> tuple[Rig, dict]:
    res = R.refine_rig(rig, recs, cameras=[cam], params=params(variant, extra_cost))
    return res.rig, res.report["cameras"][cam]


def cmd_heldout(cam: str, variant: set[str], mode: str) -> None:
    rig = Rig.load(RES / "rig.json")
    lm_fit = load(RES / "landmarks.json", rig)
    lm_out = heldout_landmarks(rig)
    print(f"start rig.json: fitted {fmt(judge(rig, lm_fit, cam))}\n   held-out {fmt(judge(rig, lm_out, cam))}")
    groups = [PLANTS] if mode == "joint" else [[p] for p in PLANTS]
    lmc = landmark_cost(rig, lm_fit, cam, variant)
    for g in groups:
        t0 = time.time()
        out, rep = refine(rig, recordings(rig, variant, g), cam, variant, lmc)
        print(f"{mode} {','.join(x[:6] for x in g)}: conv {rep['converged']} NID {rep['start_cost']:.4f}->{rep['end_cost']:.4f} "
              f"info {rep['information']:.3f} contrast {rep['contrast']:.3f} change {rep['change']} ({time.time() - t0:.0f} s)")
        pf, po = judge(out, lm_fit, cam), judge(out, lm_out, cam)
        if mode != "joint":
            pf = {k: v for k, v in pf.items() if k in g}
            po = {k: v for k, v in po.items() if k in g}
        print(f"   fitted {fmt(pf)}\n   held-out {fmt(po)}")
        sys.stdout.flush()


def cmd_lopo(cam: str, variant: set[str], mode: str) -> None:
    nominal = Rig.load(RES / "rig_nominal.json")
    lm = load(RES / "landmarks.json", nominal)
    base: dict[str, list[float]] = {}
    ref: dict[str, list[float]] = {}
    for r in lm:
        plant = r.name.split("/")[-1]
        if not any(cam in x.cameras for x in r.points):
            continue
        start = fit("joint", "ir:k1", nominal, only(lm, cam, drop_rec=r.name))  # as README "nested rows"
        b = judge(start, [r], cam)
        g = PLANTS if mode == "joint" else [plant]
        t0 = time.time()
        lmc = landmark_cost(start, only(lm, cam, drop_rec=r.name), cam, variant)
        out, rep = refine(start, recordings(start, variant, g), cam, variant, lmc)
        a = judge(out, [r], cam)
        base.update(b)
        ref.update(a)
        print(f"{plant}: LOPO start {fmt(b)} -> refined {fmt(a)}; conv {rep['converged']} "
              f"NID {rep['start_cost']:.4f}->{rep['end_cost']:.4f} change {rep['change']} ({time.time() - t0:.0f} s)")
        sys.stdout.flush()
    print(f"LOPO {cam} landmark fit: {fmt(base)}\nLOPO {cam} + refine {sorted(variant)} {mode}: {fmt(ref)}")


def cmd_scan(cam: str, plant: str, variant: set[str], png: str | None) -> None:
    rig = Rig.load(RES / "rig.json")
    lm = load(RES / "landmarks.json", rig) + (heldout_landmarks(rig) if cam == "thermal" else [])
    plants = PLANTS if plant == "all" else [plant]
    recs = recordings(rig, variant, plants)
    p = params(variant)
    dcam = rig.depth()
    camera = rig.camera(cam)
    rng = np.random.default_rng(p.seed)
    rays = R.pixel_rays_cam(dcam)
    data = [R._prepare_recording(rig, rec, rays, p, rng) for rec in recs]
    src = {i: R._single_channel(r.images[cam]) for i, r in enumerate(recs) if cam in r.images}
    f_src = float(np.sqrt(camera.K[0, 0] * camera.K[1, 1]))
    reach0 = 2.0 * p.bound_units * max(p.min_sigma_px, f_src * np.radians(max(p.levels_deg)))
    visible = {}
    for i, d in enumerate(data):
        cand = np.arange(min(len(d.X_rig), p.candidates * p.max_points))
        uv, z = R._project_uvz(camera, d.X_rig[cand])
        near = camera.in_image(uv, -reach0) & (z > 0)
        vis = np.zeros(len(d.X_rig), bool)
        vis[cand[near]] = R._visible(camera, d, cand[near], p.occlusion_tol_m, p.visibility_radius_m)
        visible[i] = vis
    names = ["image y (rot)", "image x (rot)", "roll", "tx (parallax)", "ty (parallax)", "tz"]
    rows = []
    for sig_deg in (0.2, 0.0):
        sig = max(p.min_sigma_px, f_src * np.radians(sig_deg))
        lv, zs = R._level_data(camera, dcam, data, src, sig, max(0.0, float(dcam.K[0, 0]) * np.radians(sig_deg)),
                               p, p.bound_units * sig, (rig.roi_min, rig.roi_max), visible)
        par = R._Param(camera, sig, float(np.median(zs)), False)
        steps = np.linspace(-8, 8, 33)
        for k in range(6):
            costs, lms = [], []
            for s in steps:
                c = par.camera(np.eye(6)[k] * s)
                costs.append(R._cost(lv, c)[0])
                tmp = copy.deepcopy(rig)
                R._replace(tmp, c)
                v = [x for vv in judge(tmp, [r for r in lm if r.name.split("/")[-1] in plants], cam).values() for x in vv]
                lms.append(float(np.median(v)) if v else np.nan)
            costs, lms = np.array(costs), np.array(lms)
            rows.append((sig_deg, sig, k, steps, costs, lms))
            print(f"blur {sig_deg} deg ({sig:.1f} px) {names[k]:15s}: cost min at {steps[np.argmin(costs)]:+5.1f} "
                  f"(x {sig:.1f} px), landmark min at {steps[np.nanargmin(lms)]:+5.1f}; cost at 0 {costs[16]:.4f}, "
                  f"min {costs.min():.4f}, range {costs.max() - costs.min():.4f}")
    if png:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        fig, axs = plt.subplots(2, 6, figsize=(20, 6))
        for i, (sd, sig, k, steps, costs, lms) in enumerate(rows):
            ax = axs[i // 6, k]
            ax.plot(steps * sig, costs, "b-")
            ax.set_title(f"{names[k]} blur {sd} deg", fontsize=9)
            ax2 = ax.twinx()
            ax2.plot(steps * sig, lms, "r--")
            ax.axvline(0, color="k", lw=0.5)
        fig.suptitle(f"{cam} {plant} {sorted(variant)}: NID (blue) and landmark median px (red) vs shift (px) from rig.json")
        fig.tight_layout()
        fig.savefig(png, dpi=70)


def _nid(a: np.ndarray, b: np.ndarray, bins: int = 12) -> float:
    """Plain NID of two equal-population-binned value sets (N,) each."""
    qa = np.searchsorted(np.quantile(a, np.linspace(0, 1, bins + 1)[1:-1]), a)
    qb = np.searchsorted(np.quantile(b, np.linspace(0, 1, bins + 1)[1:-1]), b)
    h = np.bincount(qa * bins + qb, minlength=bins * bins).astype(float) / len(a)
    h = h.reshape(bins, bins)

    def ent(x):
        x = x[x > 0]
        return -float(np.sum(x * np.log(x)))
    hxy = ent(h)
    return 1.0 - (ent(h.sum(0)) + ent(h.sum(1)) - hxy) / hxy


def cmd_field(cam: str, plant: str, variant: set[str], png: str, tile: int = 64, reach: int = 8) -> None:
    """Per tile of the source image: the image shift (du, dv) that minimises the NID between the
    infrared values of the depth points projected there (rig.json) and the source image, against
    the landmarks' own correction (clicked - predicted). Plant points only with ``roi``."""
    rig = Rig.load(RES / "rig.json")
    lm = [r for r in load(RES / "landmarks.json", rig) + heldout_landmarks(rig) if r.name.endswith(plant)]
    if len(lm) > 1:  # fitted and held-out points of the plant in one entry
        lm = [type(lm[0])(lm[0].name, lm[0].depth_m, [x for r in lm for x in r.points])]
    rec = recordings(rig, variant, [plant])[0]
    p = apply_variant(R.RefineParams(candidates=100), variant)  # every usable depth pixel
    d = R._prepare_recording(rig, rec, R.pixel_rays_cam(rig.depth()), p, np.random.default_rng(0))
    camera = rig.camera(cam)
    uv, z = R._project_uvz(camera, d.X_rig)
    ok = camera.in_image(uv, -reach - 2) & (z > 0)
    vis = np.zeros(len(ok), bool)
    vis[ok] = R._visible(camera, d, np.flatnonzero(ok), p.occlusion_tol_m, p.visibility_radius_m)
    if "roi" in variant:
        X = d.X_rig
        vis &= np.all((X >= rig.roi_min) & (X <= rig.roi_max), axis=1)
    blur = p.image_filter or R._blur
    src = blur(R._single_channel(rec.images[cam]), 1.0)
    ref = blur(d.ref, 0.8).ravel()[d.pix]
    shifts = [(a, b) for a in range(-reach, reach + 1) for b in range(-reach, reach + 1)]
    out = []
    for v0 in range(0, camera.height, tile):
        for u0 in range(0, camera.width, tile):
            sel = vis & (uv[:, 0] >= u0) & (uv[:, 0] < u0 + tile) & (uv[:, 1] >= v0) & (uv[:, 1] < v0 + tile)
            if sel.sum() < 400:
                continue
            costs = np.array([_nid(ref[sel], R._bilinear(src, uv[sel] + np.array(s, float))) for s in shifts])
            k = int(np.argmin(costs))
            c0 = costs[shifts.index((0, 0))]
            out.append((u0 + tile / 2, v0 + tile / 2, shifts[k][0], shifts[k][1], c0 - costs[k], costs.max() - costs[k],
                        int(sel.sum())))
    rows, _ = evaluate_landmarks(rig, only(lm, cam)) if lm else ([], [])
    lms = [(r0, None) for r0 in rows]
    print(f"{cam} {plant} {sorted(variant)}: per-tile NID shift (du, dv) px, gain at best, depth of range, points")
    for t in out:
        print(f"  tile ({t[0]:.0f}, {t[1]:.0f}): shift ({t[2]:+d}, {t[3]:+d}) gain {t[4]:.3f} range {t[5]:.3f} n {t[6]}")
    sh = np.array([(t[2], t[3]) for t in out if t[5] > 0.02])
    if len(sh):
        print(f"  median tile shift (range > 0.02, {len(sh)} tiles): ({np.median(sh[:, 0]):+.1f}, {np.median(sh[:, 1]):+.1f})")
    corr = np.array([(-r0["du"], -r0["dv"]) for r0, _ in lms])
    if len(corr):
        print(f"  landmark corrections (clicked - predicted), median ({np.median(corr[:, 0]):+.1f}, {np.median(corr[:, 1]):+.1f}): "
              + " ".join(f"({c[0]:+.1f},{c[1]:+.1f})" for c in corr))
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    img = rec.images[cam]
    fig, ax = plt.subplots(figsize=(8, 8 * camera.height / camera.width))
    ax.imshow(img if img.ndim == 3 else R._single_channel(img), cmap="gray")
    ax.scatter(uv[vis, 0][::7], uv[vis, 1][::7], s=0.2, c="y", alpha=0.3)
    for t in out:
        col = "c" if t[5] > 0.02 else "gray"
        ax.arrow(t[0], t[1], 5 * t[2], 5 * t[3], color=col, width=0.8, head_width=4)
    # landmark correction: from the rig's prediction to the clicked point (x5)
    if lm:
        pts = [x for x in lm[0].points if cam in x.cameras]
        for r0 in rows:
            c = pts[r0["index"]].cameras[cam]
            ax.arrow(c[0] + r0["du"], c[1] + r0["dv"], -5 * r0["du"], -5 * r0["dv"], color="r", width=0.8, head_width=4)
    ax.set_title(f"{cam} {plant} {sorted(variant)}: cyan = tile NID shift x5, red = landmark correction x5", fontsize=9)
    fig.tight_layout()
    fig.savefig(png, dpi=80)


def cmd_overlay(cam: str, plant: str, variant: set[str], shift: tuple[float, float], png: str,
                box: tuple[int, int, int, int] | None = None) -> None:
    """The infrared values of the depth points splatted into ``cam`` at rig.json's pose (left)
    and shifted by ``shift`` px (right); edges of the source (magenta) and of the splatted
    infrared (green) over the source, 3x, in ``box`` (u0, v0, u1, v1)."""
    rig = Rig.load(RES / "rig.json")
    rec = recordings(rig, variant, [plant])[0]
    p = R.RefineParams(candidates=100)
    d = R._prepare_recording(rig, rec, R.pixel_rays_cam(rig.depth()), p, np.random.default_rng(0))
    camera = rig.camera(cam)
    uv, z = R._project_uvz(camera, d.X_rig)
    ok = camera.in_image(uv, 0) & (z > 0)
    vis = np.zeros(len(ok), bool)
    vis[ok] = R._visible(camera, d, np.flatnonzero(ok), p.occlusion_tol_m, p.visibility_radius_m)
    src = R._single_channel(rec.images[cam])
    s8 = cv2.normalize(src, None, 0, 255, cv2.NORM_MINMAX).astype(np.uint8)
    ir = np.log1p(np.maximum(d.ref.ravel()[d.pix], 0))
    panels = []
    for sh in ((0.0, 0.0), shift):
        acc = np.zeros(src.shape, np.float64)
        cnt = np.zeros(src.shape, np.float64)
        q = np.round(uv[vis] + np.array(sh)).astype(int)
        good = (q[:, 0] >= 0) & (q[:, 0] < src.shape[1]) & (q[:, 1] >= 0) & (q[:, 1] < src.shape[0])
        np.add.at(acc, (q[good, 1], q[good, 0]), ir[vis][good])
        np.add.at(cnt, (q[good, 1], q[good, 0]), 1)
        splat = np.where(cnt > 0, acc / np.maximum(cnt, 1), np.nan).astype(np.float32)
        # fill the gaps between splatted points (the depth camera has ~1/2 the resolution)
        fill = cv2.dilate(np.nan_to_num(splat), np.ones((3, 3), np.uint8))
        splat = np.where(np.isfinite(splat), splat, fill)
        i8 = cv2.normalize(cv2.GaussianBlur(splat, (0, 0), 1.0), None, 0, 255, cv2.NORM_MINMAX).astype(np.uint8)
        e_s = cv2.Canny(cv2.GaussianBlur(s8, (0, 0), 1.2), 30, 80) > 0
        e_i = cv2.Canny(i8, 30, 80) > 0
        over = cv2.cvtColor(s8, cv2.COLOR_GRAY2BGR)
        over[e_s] = (255, 0, 255)
        over[e_i] = (0, 255, 0)
        over[e_s & e_i] = (255, 255, 255)
        u0, v0, u1, v1 = box or (0, 0, src.shape[1], src.shape[0])
        panels.append(cv2.resize(over[v0:v1, u0:u1], None, fx=3, fy=3, interpolation=cv2.INTER_NEAREST))
        panels.append(np.full((panels[-1].shape[0], 6, 3), 255, np.uint8))
    cv2.imwrite(png, np.hstack(panels[:-1]))


if __name__ == "__main__":
    a = sys.argv[1:]
    if a[0] == "scan":
        cmd_scan(a[1], a[2], set(a[3].split(",")), a[4] if len(a) > 4 else None)
    elif a[0] == "overlay":
        cmd_overlay(a[1], a[2], set(a[3].split(",")), (float(a[4]), float(a[5])), a[6],
                    tuple(int(x) for x in a[7:11]) if len(a) > 10 else None)
    elif a[0] == "field":
        cmd_field(a[1], a[2], set(a[3].split(",")), a[4])
    elif a[0] == "lopo":
        cmd_lopo(a[1], set(a[2].split(",")), a[3])
    elif a[0] == "heldout":
        cmd_heldout(a[1], set(a[2].split(",")), a[3])
    else:
        raise SystemExit(__doc__)
