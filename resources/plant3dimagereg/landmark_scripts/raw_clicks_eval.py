"""Experiment (issue 8): do the landmarks get better WITHOUT finalize.py's inward step?

Hypothesis tested: the inward step (infrared click moved onto valid depth, the other camera's
click moved by a guessed x1.8 / x2.2 along its own inward direction) injects a systematic error.
Variant ``raw``: both clicks exactly where they were read (the mean of the two eye readings,
``feature_ir`` / ``feature_other`` in annotations.json), the infrared point's depth from the
FRONT surface's local plane extrapolated to the click (``edge_depth`` below: at an occluding
edge the Azure Kinect's valid plant depth ends 2-4 px, at thin tips ~6 px, short of the clicked
silhouette; the nearest surface with a pixel within 6 px, a plane in inverse depth weighted to
its pixels nearest the click). Variant ``shipped``: landmarks.json as shipped (stepped points),
with the core's ``landmark_depth``. Both fitted with ``--free ir:k1`` from rig_nominal.json,
leave-one-plant-out (LOPO) per camera.

Result (README, "Raw clicks without the inward step"): raw is WORSE (hyperspectral LOPO 4.55 px
vs 3.14 px), so the inward step stays. ``edge_depth`` stays out of the core: on the synthetic
landmark test (clicks spread over the plant) it moved 3 of 24 clicks near an overlapping leaf's
edge onto the front leaf (outliers), i.e. the rule is wrong for clicks that are not silhouette
features.

  cd resources/plant3dimagereg/landmark_scripts && PYTHONPATH=../../.. python raw_clicks_eval.py [raw,raw_uv_stepped_z,mapped_step,shipped] [FREE]
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import numpy as np

from plantreg_gui.core.rigfit import rigfit
from plantreg_gui.core.data.landmarks import Landmark
from plantreg_gui.core.data.recording import Recording
from plantreg_gui.core.camera.rig import Rig
from plantreg_gui.core.rigfit.rigfit import RecordingLandmarks, fit_rig

HERE = Path(__file__).resolve().parent
RES = HERE.parent


def _surfaces(win: np.ndarray, ok: np.ndarray) -> np.ndarray:
    """Label map (int, 0 = none) of the window's surfaces (:func:`rigfit.grow_surface` from
    every valid pixel not yet on one)."""
    lab = np.zeros(win.shape, np.int32)
    n = 0
    for seed in zip(*np.nonzero(ok)):
        if lab[seed]:
            continue
        n += 1
        lab[rigfit.grow_surface(win, ok & (lab == 0), seed)] = n
    return lab


def edge_depth(depth_m: np.ndarray, uv: np.ndarray, radius: int = 3, min_support: int = 5,
                   reach: float = 6.0, edge: int = 2) -> tuple[float, str]:
    """Depth (metres along the optical axis) of the surface the clicked pixel ``uv`` (2,) shows.

    Surfaces are grown through small depth steps (:func:`_surfaces`); one of fewer than
    ``min_support`` pixels is a flying pixel or a sliver, never used.

    * **Inside a surface** (the click's pixel lies on one and nothing else -- no hole, no other
      surface -- within ``edge`` px): that surface, in the (2 ``radius`` + 1)^2 window.
    * **At an occluding edge** (a leaf tip, a notch, a leaf corner against the background: the
      features people click): a time-of-flight camera has no valid depth there -- mixed
      ("flying") pixels, holes, often the background right up to the edge the infrared image
      shows (measured on the Azure Kinect: the plant's valid depth ends 2-4 px, at thin tips 6 px,
      short of the clicked silhouette). The feature belongs to the *front* surface: the nearest
      surface with a pixel within ``reach`` px of the click.

    On the chosen surface a plane in inverse depth, weighted towards the click, is fitted and
    evaluated at the sub-pixel click (extrapolated a few pixels at an edge: the leaf is locally
    planar); never the flying pixel's own value.

    Returns ``(z, "")`` or ``(nan, reason)``.
    """
    H, W = depth_m.shape
    u0, v0 = int(round(float(uv[0]))), int(round(float(uv[1])))
    if not (0 <= u0 < W and 0 <= v0 < H):
        return math.nan, "outside the depth image"
    R = max(radius, int(math.ceil(reach)) + 2)
    a0, a1, b0, b1 = max(0, v0 - R), min(H, v0 + R + 1), max(0, u0 - R), min(W, u0 + R + 1)
    win = np.asarray(depth_m[a0:a1, b0:b1], dtype=np.float64)
    ok = np.isfinite(win) & (win > 0)
    cv, cu = v0 - a0, u0 - b0
    vv, uu = np.mgrid[a0:a1, b0:b1]
    du, dv = uu - float(uv[0]), vv - float(uv[1])
    dist = np.hypot(du, dv)
    core = (np.abs(vv - v0) <= radius) & (np.abs(uu - u0) <= radius)
    if (ok & core).sum() < min_support and not (ok & (dist <= reach)).any():
        return math.nan, (f"no depth at or around the pixel (only {int((ok & core).sum())} of "
                          f"{(2 * radius + 1) ** 2} pixels in the {2 * radius + 1}x{2 * radius + 1} window have depth)")
    lab = _surfaces(win, ok)
    sizes = np.bincount(lab.ravel())
    own = int(lab[cv, cu])
    near = (np.abs(vv - v0) <= edge) & (np.abs(uu - u0) <= edge)
    if own and sizes[own] >= min_support and np.all(lab[near] == own):
        sel = (lab == own) & core
        w = np.exp(-(du[sel] ** 2 + dv[sel] ** 2) / (2.0 * (0.6 * radius) ** 2))
        zc = rigfit.inverse_depth_plane(win[sel], du[sel], dv[sel], w)
        z = win[sel]
        return (float(zc), "") if np.isfinite(zc) and z.min() - 0.005 <= zc <= z.max() + 0.005 \
            else (float(np.median(z)), "")
    cands = [k for k in range(1, sizes.size)
             if sizes[k] >= min_support and dist[lab == k].min() <= reach]
    if not cands:
        return math.nan, "only scattered (flying) depth pixels around the pixel, no surface under it"
    front = min(cands, key=lambda k: float(np.median(win[lab == k])))
    sel = lab == front
    d0 = float(dist[sel].min())
    # the surface's pixels nearest the click carry the fit; farther ones keep the plane's tilt
    w = np.exp(-((dist[sel] - d0) ** 2) / (2.0 * 2.5 ** 2))
    zc = rigfit.inverse_depth_plane(win[sel], du[sel], dv[sel], w)
    nearest = win[sel][dist[sel] <= d0 + 1.0]
    if np.isfinite(zc) and abs(zc - float(np.median(nearest))) <= 0.01 + 0.01 * (d0 + 1.0):
        return float(zc), ""
    return float(np.median(nearest)), ""


_DEPTH: dict[str, np.ndarray] = {}


def mapped_step(rig: Rig, plant: str, cam: str, it: dict) -> list[float]:
    """The other camera's click moved by the image of the infrared step's 3D displacement in the
    START rig (independent of the landmarks): X_raw = front-surface point at the read infrared
    pixel (``edge_depth``), X_step = the stepped point (core depth); instead of finalize.py's
    guessed x1.8 / x2.2 along the other image's own inward direction."""
    if plant not in _DEPTH:
        _DEPTH[plant] = Recording.load(RES / "recordings" / plant).depth_m(rig.depth_scale)
    d, dcam, ocam = _DEPTH[plant], rig.depth(), rig.camera(cam)
    pts = []
    for uv, depth in ((it["feature_ir"], edge_depth), (it["ir"], rigfit.landmark_depth)):
        z, _ = depth(d, np.array(uv, float))
        pts.append(dcam.to_rig(dcam.rays_cam(np.array([uv], float)) * z))
    (a, _), (b, _) = ocam.project(pts[0]), ocam.project(pts[1])
    return (np.asarray(it["feature_other"], float) + (b[0] - a[0])).tolist()


def offset_other(it: dict, plant: str, cam: str, delta: float) -> list[float]:
    """The shipped other-camera point moved ``delta`` px further along its own inward direction
    (a per-modality edge offset: each image may draw a leaf's edge at a different place)."""
    from finalize import SCALE, inward_normal

    po = np.asarray(it["feature_other"], float)
    n = np.asarray(it["other"], float) - po
    n = n / np.linalg.norm(n) if np.linalg.norm(n) > 1e-6 else inward_normal(plant, cam, po, 8.0 * SCALE[cam])
    return (np.asarray(it["other"], float) + delta * n).tolist()


def recordings(variant: str, rig: Rig, delta: float = 0.0, only: set[str] | None = None) -> list[RecordingLandmarks]:
    ann = json.loads((HERE / "annotations.json").read_text())
    pts: dict[str, list[Landmark]] = {}
    for key, items in ann.items():
        plant, cam = key.split("/")
        for it in items:
            ir, oth = (it["ir"], it["other"]) if variant == "shipped" else (it["feature_ir"], it["feature_other"])
            if only is not None and plant not in only:
                continue
            if variant == "edge_offset":
                ir, oth = it["ir"], offset_other(it, plant, cam, delta)
            if variant == "mapped_step":
                ir, oth = it["ir"], mapped_step(rig, plant, cam, it)
            # stepped_ir: where raw_uv_stepped_z reads the depth (the validated inner point)
            pts.setdefault(plant, []).append(Landmark(np.array(ir), {cam: np.array(oth)}, it["note"],
                                                      {"stepped_ir": it["ir"]}))
    out = []
    for p, lms in sorted(pts.items()):
        rec = Recording.load(RES / "recordings" / p)
        out.append(RecordingLandmarks(f"recordings/{p}", rec.depth_m(rig.depth_scale), lms))
    return out


def nested_edge_offset(rig: Rig, free: str, deltas=np.arange(-3.0, 3.01, 0.5)) -> None:
    """Leave-one-plant-out with the hyperspectral edge offset chosen WITHOUT the held-out plant:
    per fold, the offset whose fit on the other plants has the smallest median hyperspectral
    residual; then the held-out plant's residuals with that fold's rig."""
    plants = sorted({k.split("/")[0] for k in json.loads((HERE / "annotations.json").read_text())
                     if k.endswith("/hyperspectral")})
    held = []
    for p in plants:
        rest = set(plants) - {p}
        best = None
        for d in deltas:
            try:
                r = fit_rig(rig, recordings("edge_offset", rig, d, rest), free=rigfit.parse_free(free), loo=False,
                            cameras=["hyperspectral"])
            except Exception as e:  # noqa: BLE001 - a fold without enough landmarks
                print("  fold", p, d, e)
                continue
            m = r.report["per_camera"]["hyperspectral"]["median_px"]
            if best is None or m < best[0]:
                best = (m, d, r.rig)
        rows, _ = rigfit.evaluate_landmarks(best[2], recordings("edge_offset", rig, best[1], {p}), ["hyperspectral"])
        res = [x["residual_px"] for x in rows]
        held += res
        print(f"   fold without {p}: offset {best[1]:+.1f} px (training median {best[0]:.2f}), held-out median {np.median(res):.2f}")
    print(f"== nested edge offset (free {free}): hyperspectral LOPO median {np.median(held):.2f} p90 {np.percentile(held, 90):.2f} (n {len(held)})")


def _aspect_rig(rig: Rig, axis: int, a: float) -> Rig:
    r = Rig.from_dict(rig.to_dict())
    r.camera("hyperspectral").K[axis, axis] *= a
    return r


def nested_aspect(rig: Rig, free: str, scales=np.arange(0.94, 1.061, 0.01)) -> None:
    """Leave-one-plant-out with the hyperspectral pixel aspect (fx or fy alone scaled; the Specim IQ
    scans one image axis, so its two focal lengths need not be equal) chosen WITHOUT the held-out
    plant: per fold, the (axis, scale) whose fit on the other plants has the smallest median
    hyperspectral residual; then the held-out plant with that fold's rig."""
    plants = sorted({k.split("/")[0] for k in json.loads((HERE / "annotations.json").read_text())
                     if k.endswith("/hyperspectral")})
    held = []
    for p in plants:
        rest = set(plants) - {p}
        best = None
        for axis in (0, 1):
            for a in scales:
                r = fit_rig(_aspect_rig(rig, axis, a), recordings("shipped", rig, 0.0, rest),
                            free=rigfit.parse_free(free), loo=False, cameras=["hyperspectral"])
                m = r.report["per_camera"]["hyperspectral"]["median_px"]
                if best is None or m < best[0] - 1e-9:
                    best = (m, "fx" if axis == 0 else "fy", a, r.rig)
        rows, _ = rigfit.evaluate_landmarks(best[3], recordings("shipped", rig, 0.0, {p}), ["hyperspectral"])
        res = [x["residual_px"] for x in rows]
        held += res
        print(f"   fold without {p}: {best[1]} x {best[2]:.2f} (training median {best[0]:.2f}), "
              f"held-out median {np.median(res):.2f}")
    print(f"== nested aspect (free {free}): hyperspectral LOPO median {np.median(held):.2f} "
          f"p90 {np.percentile(held, 90):.2f} (n {len(held)})")


def main() -> None:
    if sys.argv[1:2] == ["nested_aspect"]:
        return nested_aspect(Rig.load(RES / "rig_nominal.json"), sys.argv[2] if len(sys.argv) > 2 else "ir:k1")
    if sys.argv[1:2] == ["nested_edge_offset"]:
        return nested_edge_offset(Rig.load(RES / "rig_nominal.json"), sys.argv[2] if len(sys.argv) > 2 else "ir:k1")
    variants = (sys.argv[1] if len(sys.argv) > 1 else "raw,shipped").split(",")
    free = sys.argv[2] if len(sys.argv) > 2 else "ir:k1"
    rig = Rig.load(RES / "rig_nominal.json")
    core_depth = rigfit.landmark_depth
    for variant in variants:
        recs = recordings(variant, rig)
        if variant == "raw":
            rigfit.landmark_depth = edge_depth
        elif variant == "raw_uv_stepped_z":
            # both clicks where read; the depth of the inward-stepped infrared point (no extrapolation)
            z_of = {(r.name, tuple(lm.depth_uv)): core_depth(r.depth_m, np.array(lm.extra["stepped_ir"]))
                    for r in recs for lm in r.points}
            rigfit.landmark_depth = lambda d, uv, **kw: next(
                z for (n, k), z in z_of.items() if np.allclose(k, uv) and d is depth_of[n])
            depth_of = {r.name: r.depth_m for r in recs}
        try:
            rep = fit_rig(rig, recs, free=rigfit.parse_free(free), loo=True).report
        finally:
            rigfit.landmark_depth = core_depth
        print(f"== {variant} (free {free}): landmarks without depth {len(rep['landmarks_rejected'])}, "
              f"outliers {sum(d['outlier'] for d in rep['residuals'])}")
        for c, v in rep["per_camera"].items():
            lo = rep["leave_one_out"]["per_camera"].get(c, {})
            print(f"   {c:13s} fitted median {v['median_px']:.2f} p90 {v['p90_px']:.2f} (n {v['n']})   "
                  f"LOPO median {lo.get('median_px', math.nan):.2f} p90 {lo.get('p90_px', math.nan):.2f} (n {lo.get('n', 0)})")
        for r, v in rep["leave_one_out"]["per_recording"].items():
            print(f"   LOPO {r}: " + ", ".join(f"{c} {s['median_px']:.2f}" if "median_px" in s else f"{c} -"
                                           for c, s in v.items() if isinstance(s, dict)))


if __name__ == "__main__":
    main()
