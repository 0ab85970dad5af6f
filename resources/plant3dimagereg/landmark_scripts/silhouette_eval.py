"""Measure the silhouette (outline) fit on the real plants (README "Silhouette fit").

Run from the project root with the venv's python and PYTHONPATH = project root:

  python resources/plant3dimagereg/landmark_scripts/silhouette_eval.py agree [RIG]          # outline agreement of a rig
  python resources/plant3dimagereg/landmark_scripts/silhouette_eval.py only CAM nominal|rig # outlines alone, no landmarks
  python resources/plant3dimagereg/landmark_scripts/silhouette_eval.py lopo CAM K[,K...] [free_focal=1]
  python resources/plant3dimagereg/landmark_scripts/silhouette_eval.py clicks CAM         # where the clicks sit in the masks

``lopo``: for each plant with landmarks of CAM, the start is the landmark fit (``rigfit``,
``--free ir:k1``, this camera) on the OTHER plants' landmarks (the nominal rig where they are
fewer than 6), then ``silhouette.fit_camera`` with the outlines of all five plants (outlines use
no clicks) weighted ``points_weight = K`` and the other plants' landmarks; the held-out plant's
landmarks are measured against it. K = 0: landmarks alone (same loss and priors). Also prints the
fit on all landmarks ("all-fit", residuals on points used in the fit).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

from plantreg_gui.core.rigfit import rigfit
from plantreg_gui.core.rigfit import silhouette as S
from plantreg_gui.core.data.landmarks import LandmarkSet
from plantreg_gui.core.data.recording import Recording
from plantreg_gui.core.camera.rig import Rig

R = Path(__file__).resolve().parents[1]
PL = "01grapevine 02leopard_lily 03areca_palm 04philodendron 05boston_fern".split()  # weeping fig: no usable mask
SIGMA = {"hyperspectral": 1.1, "thermal": 1.4}  # one reading's error (re-click table)
lms = LandmarkSet.load(R / "landmarks.json")
nominal = Rig.load(R / "rig_nominal.json")
shipped = Rig.load(R / "rig.json")
recs = {p: Recording.load(R / "recordings" / p) for p in PL}
depth = {p: recs[p].depth_m(shipped.depth_scale) for p in PL}


def points(rig: Rig, cam: str, p: str) -> tuple[np.ndarray, np.ndarray]:
    pts = [lm for lm in lms.recordings.get("recordings/" + p, []) if cam in lm.cameras]
    if not pts:
        return np.zeros((0, 3)), np.zeros((0, 2))
    X, ok = S.landmark_points(rig, depth[p], np.array([lm.depth_uv for lm in pts]))
    return X[ok], np.array([lm.cameras[cam] for lm in pts])[ok]


def errors(rig: Rig, cam_obj, cam: str, plants) -> dict[str, np.ndarray]:
    out = {}
    for p in plants:
        X, uv = points(rig, cam, p)
        if len(uv):
            out[p] = np.linalg.norm(cam_obj.project(X)[0] - uv, axis=1)
    return out


def summary(res: dict[str, np.ndarray]) -> str:
    a = np.concatenate(list(res.values()))
    return (f"n {len(a)} median {np.median(a):.2f} p90 {np.percentile(a, 90):.2f} | "
            + " ".join(f"{k}: {np.median(v):.2f}" for k, v in res.items()))


def agree(rig_path: str) -> None:
    rig = Rig.load(rig_path)
    for cam in ("hyperspectral", "thermal"):
        for p in PL:
            v = S.make_view(rig, cam, p, depth[p], recs[p].images[cam])
            a = S.outline_agreement(rig.camera(cam), v)
            print(f"{cam:14s} {p:16s} points {a['points']:5d}  median |d| {a['median_abs_px']:.2f} px  "
                  f"within 2 px {a['within_2px']:.2f}  offset {a['offset_px']:+.2f}  "
                  f"shift ({a['shift_px'][0]:+.2f}, {a['shift_px'][1]:+.2f}) |{np.hypot(*a['shift_px']):.2f}| px")


def only(cam: str, start_name: str) -> None:
    start = nominal if start_name == "nominal" else shipped
    vs = [S.make_view(start, cam, p, depth[p], recs[p].images[cam]) for p in PL]
    t = time.time()
    r = S.fit_camera(start, cam, vs)
    print(f"{cam} start ({start_name}):", summary(errors(start, start.camera(cam), cam, PL)))
    print(f"{cam} outlines only:", summary(errors(start, r.camera, cam, PL)), f"({time.time() - t:.0f} s)")
    for p, v in zip(PL, vs):
        a = S.outline_agreement(r.camera, v)
        sx, sy = a["shift_px"]
        print(f"   {p:16s} median |d| {a['median_abs_px']:.2f}  shift ({sx:+.2f}, {sy:+.2f})")


def lopo(cam: str, Ks: list[float], extra: dict[str, str]) -> None:
    lm_plants = [p for p in PL if len(points(shipped, cam, p)[1])]
    res: dict[float, dict] = {K: {} for K in Ks}
    for held in lm_plants + ["ALL"]:
        train = [p for p in PL if p != held]
        sub = LandmarkSet({k: v for k, v in lms.recordings.items() if k.split("/")[-1] in train},
                          base=lms.base, path=lms.path)
        try:
            frig = rigfit.fit_rig_from_file(nominal, sub, free=rigfit.parse_free("ir:k1"), loo=False, cameras=[cam]).rig
        except Exception as e:  # fewer than 6 landmarks in the fold
            print(f"fold without {held}: {e}; nominal start")
            frig = nominal
        for K in Ks:
            prm = S.SilhouetteParams(points_weight=max(K, 1e-9), landmark_px={cam: SIGMA[cam]},
                                     free_focal=bool(int(extra.get("free_focal", "0"))))
            vs = []
            for p in PL:
                v = S.make_view(frig, cam, p, depth[p], recs[p].images[cam], prm)
                if K == 0:
                    v.X_rig = v.X_rig[:0]
                if p in train:
                    v.lm_X, v.lm_uv = points(frig, cam, p)
                vs.append(v)
            r = S.fit_camera(frig, cam, vs, prm, use_silhouette=K > 0)
            for p, e in errors(frig, r.camera, cam, [held] if held != "ALL" else lm_plants).items():
                res[K][(held, p)] = e
    for K in Ks:
        lo = {p: e for (h, p), e in res[K].items() if h != "ALL"}
        al = {p: e for (h, p), e in res[K].items() if h == "ALL"}
        print(f"K={K:g} leave-one-plant-out: {summary(lo)}  ||  all-fit: {summary(al)}")


def clicks(cam: str) -> None:
    """Signed distance of every landmark click to its own image's plant outline (< 0 = inside)."""
    ds, dd = [], []
    for p in PL:
        pts = [lm for lm in lms.recordings.get("recordings/" + p, []) if cam in lm.cameras]
        if not pts:
            continue
        sdf_s = S.signed_distance(S.source_plant_mask(recs[p].images[cam]))
        sdf_d = S.signed_distance(S.depth_plant_mask(shipped, depth[p]))
        for lm in pts:
            ds.append(float(S._sample(sdf_s, lm.cameras[cam][None])[0]))
            dd.append(float(S._sample(sdf_d, lm.depth_uv[None])[0]))
            print(f"{p:16s} {cam} click {ds[-1]:+.2f} px  depth-camera click {dd[-1]:+.2f} px  {lm.note[:50]}")
    print(f"median: {cam} clicks {np.median(ds):+.2f} px from the {cam} outline, depth-camera clicks "
          f"{np.median(dd):+.2f} px from the depth outline")


if __name__ == "__main__":
    what = sys.argv[1]
    if what == "agree":
        agree(sys.argv[2] if len(sys.argv) > 2 else str(R / "rig.json"))
    elif what == "only":
        only(sys.argv[2], sys.argv[3])
    elif what == "clicks":
        clicks(sys.argv[2])
    elif what == "lopo":
        lopo(sys.argv[2], [float(k) for k in sys.argv[3].split(",")], dict(a.split("=") for a in sys.argv[4:]))
    else:
        raise SystemExit(__doc__)
