"""Synthetic landmarks with known truth, and rough start rigs, for testing landmark fits."""

from __future__ import annotations

import cv2
import numpy as np

from ..data.landmarks import Landmark
from ..camera.rig import Rig
from .scene import MAT_GROUND, Scene


def synthetic_landmarks(rig: Rig, scene: Scene, n: int = 12, noise_px: float = 0.7,
                        rng: np.random.Generator | None = None, sources: list[str] | None = None,
                        candidates: int = 4000) -> list[Landmark]:
    """Landmarks as a careful user clicks them: ``n`` depth-camera pixel centres on the object (pot,
    soil, stems, leaves) that every source sees, spread over the object (farthest-point sampling
    in 3D from a random start among ``candidates`` random object pixels), with the TRUE surface
    point projected into each source by ``rig`` (the true rig) plus Gaussian click noise of
    ``noise_px`` per axis."""
    rng = rng if rng is not None else np.random.default_rng(0)
    cam = rig.depth()
    srcs = [rig.camera(s) for s in (sources or [c.name for c in rig.cameras if c.name != cam.name])]
    px = cam.pixel_grid()
    o, d = cam.rays_rig(px)
    _t, prim, _bary = scene.cast(o, d)
    obj = np.flatnonzero(prim >= 0)
    obj = obj[scene.material[prim[obj]] > MAT_GROUND]
    cand = rng.choice(obj, min(candidates, len(obj)), replace=False)
    P = scene.refine(o, d[cand], prim[cand])
    ok = np.ones(len(cand), bool)
    uvs = {}
    for s in srcs:
        uv, z = s.project(P)
        ok &= (z > 0) & s.in_image(uv, margin=1.0)
        C = s.center_rig
        vec = P - C
        D = np.linalg.norm(vec, axis=1)
        t, _p, _b = scene.cast(C, vec / D[:, None])
        ok &= t >= D - 1e-3  # visible from the source
        uvs[s.name] = uv
    idx = np.flatnonzero(ok)
    if len(idx) < n:
        raise ValueError(f"only {len(idx)} object pixels are seen by every source")
    pick = [int(idx[rng.integers(len(idx))])]
    dmin = np.linalg.norm(P[idx] - P[pick[0]], axis=1)
    while len(pick) < n:
        j = int(np.argmax(dmin))
        pick.append(int(idx[j]))
        dmin = np.minimum(dmin, np.linalg.norm(P[idx] - P[idx[j]], axis=1))
    out = []
    for i in pick:
        cams = {s.name: uvs[s.name][i] + rng.normal(0.0, noise_px, 2) for s in srcs}
        out.append(Landmark(px[cand[i]], cams, note=f"synthetic, true point {np.round(P[i], 4).tolist()}"))
    return out


def perturb_rig(rig: Rig, rng: np.random.Generator, rotation_deg: float = 3.0, position_m: float = 0.03,
                focal_rel: float = 0.03, cameras: list[str] | None = None) -> Rig:
    """A copy of ``rig`` whose cameras (all but the depth camera unless ``cameras``) are rotated by
    ``rotation_deg`` about a random axis, moved by ``position_m`` in a random direction and have
    their focal lengths scaled by ``1 +/- focal_rel`` (random sign)."""
    out = Rig.from_dict(rig.to_dict())
    names = cameras if cameras is not None else [c.name for c in out.cameras if c.name != out.depth_camera]
    for name in names:
        c = out.camera(name)
        ax = rng.normal(size=3)
        ax /= np.linalg.norm(ax)
        C = c.center_rig
        mv = rng.normal(size=3)
        mv /= np.linalg.norm(mv)
        R = cv2.Rodrigues(ax * np.radians(rotation_deg))[0] @ c.R_cam_rig
        c.R_cam_rig, c.t_cam_rig = R, -R @ (C + position_m * mv)
        s = 1.0 + focal_rel * float(rng.choice([-1.0, 1.0]))
        c.K[0, 0] *= s
        c.K[1, 1] *= s
    return out
