"""How well can any rigid camera pose explain one plant's landmarks? (issue 8, session 6)

For every plant with at least 6 landmarks of a camera, the camera's pose is fitted to that
plant's own landmarks alone and the residuals are measured on the same landmarks (in-sample: an
optimistic figure; a held-out residual is larger). Two independent fitters:

* ``PnP``: plain least squares, OpenCV only — the landmarks' 3D points from the depth map
  (``core.rigfit.landmark_depth`` under the click, back-projected with the infrared camera of
  RIG), ``cv2.solvePnP`` (SQPnP) then ``cv2.solvePnPRefineLM`` with the source camera's
  intrinsics from RIG; no priors, no robust loss.
* ``fit-rig FREE``: ``core.rigfit.fit_rig`` on that plant's landmarks of that camera only
  (robust loss, weak priors), poses only or with intrinsics freed as well.

If a plant's own pose leaves a median residual of ``m`` px on its own landmarks, no rig (one pose
per camera for all plants) can be expected to do better than ``m`` on that plant's landmarks,
and a leave-one-plant-out figure is larger still.

    cd resources/plant3dimagereg/landmark_scripts && PYTHONPATH=../../.. python pose_bound.py [RIG]

RIG: default ``../rig.json``. Landmarks: ``landmarks.json`` and ``landmarks_heldout.json``.
"""

from __future__ import annotations

import sys
from pathlib import Path

import cv2
import numpy as np

from plantreg_gui.core.camera.rig import Rig
from plantreg_gui.core.rigfit.rigfit import RecordingLandmarks, evaluate_landmarks, fit_rig, landmark_depth, parse_free

sys.path.insert(0, str(Path(__file__).resolve().parent))
from thermal_eval import RES, all_landmarks, only  # noqa: E402

FREES = ("", "ir:k1", "ir:k1,ir:principal,hyperspectral:focal,hyperspectral:k1")


def pnp_residuals(rig: Rig, rec: RecordingLandmarks, cam: str) -> np.ndarray | None:
    """In-sample residuals (n,) px of the least-squares pose of ``cam`` on ``rec``'s landmarks."""
    ir, C = rig.depth(), rig.camera(cam)
    X_ir, uv = [], []
    for lm in rec.points:
        if cam not in lm.cameras:
            continue
        z, _ = landmark_depth(rec.depth_m, np.asarray(lm.depth_uv, float))
        if not np.isfinite(z):
            continue
        n = cv2.undistortPoints(np.asarray(lm.depth_uv, float).reshape(1, 1, 2), ir.K, ir.dist).reshape(2)
        X_ir.append((n[0] * z, n[1] * z, z))
        uv.append(lm.cameras[cam])
    if len(X_ir) < 6:
        return None
    X, x = np.asarray(X_ir, float), np.asarray(uv, float)
    _, rvec, tvec = cv2.solvePnP(X, x, C.K, C.dist, flags=cv2.SOLVEPNP_SQPNP)
    rvec, tvec = cv2.solvePnPRefineLM(X, x, C.K, C.dist, rvec, tvec)
    proj = cv2.projectPoints(X, rvec, tvec, C.K, C.dist)[0].reshape(-1, 2)
    return np.hypot(*(proj - x).T)


def main(argv: list[str]) -> int:
    rig = Rig.load(Path(argv[0]) if argv else RES / "rig.json")
    recs = all_landmarks(rig)
    print("| camera | plant | n | fitter | in-sample median / max px | residuals px (sorted) |")
    print("|---|---|---:|---|---:|---|")
    for cam in ("hyperspectral", "thermal"):
        for rec in only(recs, cam):
            r = pnp_residuals(rig, rec, cam)
            if r is None:
                print(f"| {cam} | {rec.name} | {len(rec.points)} | - | too few for a pose (6) | |")
                continue
            rows = [("PnP (least squares)", r)]
            for free in FREES if cam == "hyperspectral" else FREES[:1]:
                fitted = fit_rig(rig, [rec], free=parse_free(free) if free else frozenset(), loo=False).rig
                res, _ = evaluate_landmarks(fitted, [rec], [cam])
                rows.append((f"fit-rig {free or 'pose'}", np.array([d["residual_px"] for d in res])))
            for name, v in rows:
                print(f"| {cam} | {rec.name} | {v.size} | {name} | {np.median(v):.2f} / {v.max():.1f} | "
                      f"{', '.join(f'{x:.1f}' for x in np.sort(v))} |")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
