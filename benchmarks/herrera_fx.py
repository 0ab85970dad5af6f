"""Where the Kinect's focal length on Herrera et al.'s set comes from (issue 19: within 0.1 % of the
published 1059.73 px; docs/calibration.md has the figures and what they mean). One thing changed at
a time against plantreg's full calibration of all 92 images:

    PYTHONPATH=. .venv/bin/python benchmarks/herrera_fx.py [--what corners,models,...] [--toolbox-mat FILE]

* ``corners`` (a): plantreg's corners against OpenCV's plain pipeline's (classic detector,
  ``cornerSubPix`` 11 x 11; the benchmark's, :func:`bench_calibrate.opencv_baseline`) per view,
  ``calibrateCamera`` on each, and plantreg's corners refined again with other windows.
* ``models`` (b): each camera's lens model held at one candidate (Kinect x external).
* ``joint`` (c): the Kinect alone, jointly, and without the per-camera noise weights or the robust loss.
* ``weak`` (d): the views the report lists as weak left out (all, then each Kinect one).
* ``prior`` (e): without the principal point prior.
* ``folds``: the lens model chosen with other splits of the views into cross-validation folds.
* ``poses`` (not by default: 54 calibrations): each pose left out in turn.
* ``--toolbox-mat``: the toolbox's full_set.mat (PyojinKim/Kinect_calibration_toolbox,
  dataset_original/full_set.mat; not in the shared data): its RGB-only calibration (calib0) and
  plantreg's solver on the toolbox's own corners.

Each line gives both focal lengths (and % from the published ones) and the external camera's pose
against the published one. The session is laid out over the read-only set in a temporary folder.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from contextlib import contextmanager
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
sys.path.insert(0, str(ROOT / "benchmarks"))

from bench_calibrate import opencv_baseline  # noqa: E402
from realcal import herrera_reference, herrera_session  # noqa: E402

from plantreg_gui.core.calibration import bundle as B, lensmodel as L  # noqa: E402
from plantreg_gui.core.calibration.corners import min_spacing  # noqa: E402
from plantreg_gui.core.calibration.detect import detect_session  # noqa: E402
from plantreg_gui.core.calibration.session import Session  # noqa: E402

C = sys.modules["plantreg_gui.core.calibration.calibrate"]  # the module (the package exports its function)


def _angle_deg(R: np.ndarray) -> float:
    return float(np.degrees(np.arccos(np.clip((np.trace(R) - 1) / 2, -1, 1))))


@contextmanager
def patched(obj, name: str, value):
    old = getattr(obj, name)
    setattr(obj, name, value)
    try:
        yield
    finally:
        setattr(obj, name, old)


class Run:
    def __init__(self, session: Session, ref: dict):
        self.s, self.ref = session, ref
        self.dets = {d.key: d for d in detect_session(session) if d.corners is not None}

    def line(self, label: str, dets=None, cams=None, excluded=frozenset()) -> "C.Calibration":
        s = self.s if cams is None else replace(self.s, cameras={c: self.s.cameras[c] for c in cams})
        d = {k: v for k, v in (dets or self.dets).items() if cams is None or k[1] in cams}
        cal = C.calibrate(s, d, excluded=set(excluded))
        out = []
        for c, cc in cal.intrinsics.items():
            f = cc.K[0, 0]
            out.append(f"{c} fx {f:.2f} ({100 * (f / self.ref['K_' + c][0, 0] - 1):+.3f} %, {cc.model.model.name})")
        if "external" in cal.intrinsics and len(cal.intrinsics) > 1:
            e = cal.rig.camera("external")
            out.append(f"pose {_angle_deg(e.R_cam_rig @ self.ref['R_ext_kinect'].T):.3f} deg "
                       f"{1000 * np.linalg.norm(e.t_cam_rig - self.ref['t_ext_kinect']):.2f} mm")
        print(f"{label}: " + "; ".join(out), flush=True)
        return cal


def _ordered_like(c: np.ndarray, like: np.ndarray, board) -> np.ndarray:
    """Corners ``c`` (N, 2) in the grid order (of the four a chessboard detector may return) nearest ``like``."""
    idx = np.arange(board.rows * board.columns).reshape(board.rows, board.columns)
    orders = [o.ravel() for o in (idx, idx[::-1], idx[:, ::-1], idx[::-1, ::-1])]
    return c[min(orders, key=lambda o: float(np.sum(np.linalg.norm(c[o] - like, axis=1))))]


def _compare(name: str, other: dict, mine: dict) -> None:
    for cam in ("kinect", "external"):
        rows = []
        for (p, c), o in other.items():
            if c != cam:
                continue
            m = mine[(p, c)]
            d = o - m
            r = m - m.mean(0)
            rows.append((*d.mean(0), np.sqrt(np.mean(np.sum((d - d.mean(0)) ** 2, 1))), np.sum(d * r) / np.sum(r * r)))
        a = np.array(rows)
        print(f"  {name} - plantreg corners, {cam} ({len(a)} views): mean offset {a[:, 0].mean():+.3f}, "
              f"{a[:, 1].mean():+.3f} px; RMS after the offset median {np.median(a[:, 2]):.3f}, max {a[:, 2].max():.3f} px; "
              f"scale median {1e4 * np.median(a[:, 3]):+.2f}e-4")


def _calibrate_camera(board, corners: dict, cam: str, size) -> float:
    ks = sorted(k for k in corners if k[1] == cam)
    obj = board.object_points().astype(np.float32)
    return float(cv2.calibrateCamera([obj] * len(ks), [corners[k].astype(np.float32) for k in ks], size, None, None)[1][0, 0])


def corners(run: Run) -> None:
    b = run.s.board
    mine = {k: d.corners.astype(np.float64) for k, d in run.dets.items()}
    cv_ = opencv_baseline(run.s.folder, ["kinect", "external"], b.pattern_size, b.square_size)["corners"]
    theirs = {(p, c): _ordered_like(v.reshape(-1, 2).astype(np.float64), mine[(p, c)], b)
              for c, per in cv_.items() for p, v in per.items()}
    _compare("OpenCV", theirs, mine)
    size = {c: run.dets[k].image_size for k in run.dets for c in [k[1]]}
    for cam in ("kinect", "external"):
        print(f"  calibrateCamera {cam}: on plantreg's corners fx {_calibrate_camera(b, mine, cam, size[cam]):.2f}, "
              f"on OpenCV's {_calibrate_camera(b, theirs, cam, size[cam]):.2f}")
    crit = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 50, 1e-4)
    grey = {(p, c): cv2.imread(str(run.s.pose(p).images[c]), cv2.IMREAD_GRAYSCALE).astype(np.float32)
            for p, c in run.dets}
    for label, win in [(f"half-window {w} px", (lambda s, w=w: min(w, int(0.45 * s)))) for w in (3, 5, 7)] + \
                      [(f"half-window {f} x spacing", (lambda s, f=f: int(f * s))) for f in (0.15, 0.25, 0.4)]:
        again = {}
        for k, c in mine.items():
            w = max(2, win(min_spacing(c, b)))
            again[k] = cv2.cornerSubPix(grey[k], c.astype(np.float32).reshape(-1, 1, 2), (w, w), (-1, -1),
                                        crit).reshape(-1, 2)
        print(f"  refined again, {label}: calibrateCamera kinect {_calibrate_camera(b, again, 'kinect', size['kinect']):.2f}")
        run.line(f"  refined again, {label}, plantreg joint", {k: replace(d, corners=again[k]) for k, d in run.dets.items()})


def _force(models: dict[str, str]):
    orig = L.choose_model

    def choose(name, obj, img, size, candidates=L.MODELS, rng_seed=0):
        if name in models:
            candidates = tuple(m for m in candidates if m.name == models[name])
        return orig(name, obj, img, size, candidates, rng_seed)
    return patched(C, "choose_model", choose)


def models(run: Run) -> None:
    for mk in ("k1k2k3-tan", "rational"):
        for me in ("k1k2-tan", "k1k2k3-tan", "rational"):
            with _force({"kinect": mk, "external": me}):
                run.line(f"  kinect {mk}, external {me}")


def _stereo(run: Run, corners: dict) -> str:
    """OpenCV on the poses both cameras saw: the Kinect alone, then ``stereoCalibrate`` with every
    intrinsic free (started from each camera's own ``calibrateCamera``)."""
    obj = run.s.board.object_points().astype(np.float32)
    shared = sorted(p for p, c in corners if c == "external")
    fit = {}
    for cam in ("kinect", "external"):
        pts = [corners[(p, cam)].astype(np.float32) for p in shared]
        fit[cam] = cv2.calibrateCamera([obj] * len(shared), pts, run.dets[(shared[0], cam)].image_size, None, None)
    st = cv2.stereoCalibrate([obj] * len(shared), *[[corners[(p, c)].astype(np.float32) for p in shared]
                                                     for c in ("kinect", "external")],
                             *[a.copy() for c in ("kinect", "external") for a in fit[c][1:3]],  # changed in place
                             run.dets[(shared[0], "kinect")].image_size, flags=0,
                             criteria=(cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 100, 1e-9))
    return (f"{len(shared)} shared poses: kinect alone {fit['kinect'][1][0, 0]:.2f}, stereoCalibrate kinect "
            f"{st[1][0, 0]:.2f}, external {st[3][0, 0]:.1f}")


def joint(run: Run) -> None:
    run.line("  kinect alone", cams=["kinect"])
    print("  OpenCV on plantreg's corners, " + _stereo(run, {k: d.corners for k, d in run.dets.items()}))
    orig = B.bundle_adjust

    def no_noise(*a, **k):
        k.pop("noise", None)
        return orig(*a, **k)

    def no_loss(*a, **k):
        k["f_scale"] = 1e6
        return orig(*a, **k)
    with patched(C, "bundle_adjust", no_noise):
        run.line("  joint, without the per-camera noise weights")
    with _force({"kinect": "k1k2k3-tan", "external": "k1k2k3-tan"}), patched(C, "bundle_adjust", no_loss), \
            patched(L, "bundle_adjust", no_loss):
        run.line("  kinect alone, 5 coefficients, without the robust loss", cams=["kinect"])
        run.line("  joint, 5 coefficients both, without the robust loss")


def weak(run: Run) -> None:
    cal = run.line("  all views")
    listed = {(p, c) for p, c, _e, _r in cal.weak_views}
    run.line(f"  without the {len(listed)} weak views", excluded=listed)
    for k in sorted(k for k in listed if k[1] == "kinect"):
        run.line(f"  without {k[0]}:{k[1]}", excluded={k})


def prior(run: Run) -> None:
    with patched(L, "PP_PRIOR_FRAC", 1e3):
        run.line("  without the principal point prior")


def folds(run: Run) -> None:
    b = run.s.board
    obj = b.object_points().astype(np.float64)
    for cam in ("kinect", "external"):
        views = sorted(k for k in run.dets if k[1] == cam)
        img = [run.dets[k].corners.astype(np.float64) for k in views]
        for seed in range(8):
            ch, _fit = L.choose_model(cam, [obj] * len(img), img, run.dets[views[0]].image_size, rng_seed=seed)
            cv = ", ".join(f"{n} {v:.4f}" for n, v in ch.cv_px.items() if v is not None)
            print(f"  {cam}, fold split rng_seed {seed}: {ch.model.name} (cross-validated px: {cv})", flush=True)


def poses(run: Run) -> None:
    for p in sorted({k[0] for k in run.dets}):
        run.line(f"  without {p}", excluded={k for k in run.dets if k[0] == p})


def toolbox(run: Run, mat: Path) -> None:
    import scipy.io as sio

    m = sio.loadmat(str(mat))
    c0 = m["calib0"][0, 0]
    rR, rt = c0["rR"][0, 1], c0["rt"][0, 1].ravel()
    print(f"  the toolbox's RGB-only calibration (calib0): kinect fx {c0['rK'][0, 0][0, 0]:.2f}, external "
          f"{c0['rK'][0, 1][0, 0]:.2f}; pose {_angle_deg(rR.T @ run.ref['R_ext_kinect'].T):.3f} deg "
          f"{1000 * np.linalg.norm(-rR.T @ rt - run.ref['t_ext_kinect']):.2f} mm from the published one")
    mine = {k: d.corners.astype(np.float64) for k, d in run.dets.items()}
    theirs = {}
    for ci, cam in enumerate(("kinect", "external")):
        for i, p in enumerate(m["rgb_grid_p"][0, ci][0]):
            k = (f"view_{i:04d}", cam)
            if p.size and k in mine:
                theirs[k] = _ordered_like(p.T.astype(np.float64), mine[k], run.s.board)
    _compare("the toolbox's", theirs, mine)
    run.line("  plantreg on the toolbox's corners", {k: replace(d, corners=theirs[k].astype(np.float32))
                                                    for k, d in run.dets.items() if k in theirs})


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=ROOT.parent / "shared" / "data")
    ap.add_argument("--what", default="joint,prior,weak,models,folds,corners")
    ap.add_argument("--toolbox-mat", type=Path, help="the toolbox's dataset_original/full_set.mat")
    a = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="herrera_fx_") as tmp:
        run = Run(Session.load(herrera_session(a.data, Path(tmp) / "herrera")), herrera_reference(a.data))
        run.line("plantreg")
        steps = {"corners": corners, "models": models, "joint": joint, "weak": weak, "prior": prior, "folds": folds,
                 "poses": poses}
        for w in a.what.split(","):
            print(w)
            steps[w](run)
        if a.toolbox_mat:
            print("toolbox")
            toolbox(run, a.toolbox_mat)


if __name__ == "__main__":
    main()
