"""The paper's three error tables and the ToF bias check.

Every figure is a *mean distance in pixels of the camera where it is measured*, and the same
number normalised by that camera's ``1000 / sqrt(h * w)`` (so cameras of different resolution
compare). Rows (origins) and columns (targets) of the pair tables are cameras; the diagonal is
left out.

* **intrinsic** (per camera): detected corner vs the corner projected with the calibrated
  intrinsics and the view's own board pose (PnP with the final model). Measures how well the
  lens model fits.
* **extrinsic** (origin -> target, epipolar): for each corner detected by both cameras in a pose,
  the distance of the target's detected corner to the epipolar line of the origin's corner.
  Computed on undistorted coordinates (both corners undistorted with their camera's model, the
  line from the essential matrix of the calibrated relative pose) and expressed in the target's
  *undistorted pixel* units (the target's K without distortion) -- equal to image pixels up to
  the local distortion scale (< 1 % here). Measures the relative rotation/translation (along the
  epipolar direction only).
* **depth** (origin -> target): each detected corner of the origin is carried through the mesh of
  that pose's measured depth map into the target (``register.transport_pixels``: the registration
  engine's own mesh and ray caster) and compared with the target's detected corner. Measures
  what registration will see: calibration + depth-map errors together.
* **ToF bias** (per pose): the board plane from the calibration (joint board pose) against the
  depth map inside the detected corners: median(measured z - plane z) in mm. The Azure Kinect's
  spec for systematic error is < 11 mm + 0.1 % of the distance.
"""

from __future__ import annotations

import csv
import io
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from ..errors import InputError
from ..io.imageio import atomic_write_text, read_image
from ..progress import Reporter, ensure_reporter
from .calibrate import Calibration, _per_view_errors, oriented_views, usable_views
from .detect import Detection
from .session import Session, view_key

TOF_SPEC_MM, TOF_SPEC_REL = 11.0, 0.001


def _cell(values: list[np.ndarray], norm: float) -> dict[str, Any] | None:
    if not values:
        return None
    v = np.concatenate(values)
    v = v[np.isfinite(v)]
    if not len(v):
        return None
    px = float(np.mean(v))
    return {"px": px, "normalized": px * norm, "median_px": float(np.median(v)), "n": int(len(v))}


@dataclass
class CalibrationReport:
    """``intrinsic`` {cam: {"px", "normalized", ...}}; ``extrinsic`` / ``depth`` {origin: {target:
    {"px", "normalized", ...} or None}} (``depth`` None without a depth camera);
    ``views`` per-view breakdowns {"intrinsic": {cam: {pose: px}}, "extrinsic": {o: {t: {pose: px}}},
    "depth": {o: {t: {pose: px}}}}; ``depth_bias_mm`` {pose: mm}; ``depth_bias`` {pose: {"bias_mm",
    "distance_m", "spec_mm", "within_spec", "n_pixels"}}; ``cameras`` {cam: {"width", "height",
    "normalization"}}; ``weak_views`` [{"pose", "camera", "px", "reason"}] worst first."""

    intrinsic: dict[str, dict[str, Any] | None]
    extrinsic: dict[str, dict[str, dict[str, Any] | None]]
    depth: dict[str, dict[str, dict[str, Any] | None]] | None
    views: dict[str, Any]
    depth_bias_mm: dict[str, float]
    depth_bias: dict[str, dict[str, Any]] = field(default_factory=dict)
    cameras: dict[str, dict[str, Any]] = field(default_factory=dict)
    weak_views: list[dict[str, Any]] = field(default_factory=list)
    excluded: list[str] = field(default_factory=list)
    #: camera -> :meth:`~.uncertainty.CameraUncertainty.to_dict` (standard errors, projection
    #: uncertainty grid and summary, "add views here") plus "lens_model" (the choice and its
    #: cross-validated errors)
    uncertainty: dict[str, dict[str, Any]] = field(default_factory=dict)
    #: the uncertainty limits exceeded (kept only with --accept-uncertain / the wizard's confirmation)
    accepted_uncertain: list[str] = field(default_factory=list)
    #: problems worth a line in the report and on stderr (e.g. a depth map without valid pixels)
    warnings: list[str] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        return {
            "format": "plantreg.calibration-report", "version": 1,
            "intrinsic": self.intrinsic, "extrinsic": self.extrinsic, "depth": self.depth,
            "views": self.views, "depth_bias_mm": self.depth_bias_mm, "depth_bias": self.depth_bias,
            "cameras": self.cameras, "weak_views": self.weak_views, "excluded": self.excluded,
            "warnings": self.warnings, "uncertainty": self.uncertainty,
            "accepted_uncertain": self.accepted_uncertain,
        }

    # ------------------------------------------------------------------ CSV
    def csv_tables(self) -> dict[str, str]:
        """Table name -> CSV text: ``intrinsic``, ``extrinsic_px``, ``extrinsic_normalized``,
        ``depth_px``, ``depth_normalized`` (with a depth camera) and ``depth_bias``."""
        out: dict[str, str] = {}
        cams = list(self.cameras)
        buf = io.StringIO()
        w = csv.writer(buf, lineterminator="\n")
        w.writerow(["camera", "px", "normalized", "n_corners"])
        for c in cams:
            e = self.intrinsic.get(c)
            w.writerow([c, _fmt(e, "px"), _fmt(e, "normalized"), "" if e is None else e["n"]])
        out["intrinsic"] = buf.getvalue()
        if self.uncertainty:
            out["uncertainty"] = self._uncertainty_csv()
        for name, table in (("extrinsic", self.extrinsic), ("depth", self.depth)):
            if table is None:
                continue
            for unit in ("px", "normalized"):
                buf = io.StringIO()
                w = csv.writer(buf, lineterminator="\n")
                w.writerow(["origin \\ target"] + cams)
                for o in cams:
                    w.writerow([o] + ["" if o == t else _fmt(table.get(o, {}).get(t), unit) for t in cams])
                out[f"{name}_{unit}"] = buf.getvalue()
        if self.depth_bias:
            buf = io.StringIO()
            w = csv.writer(buf, lineterminator="\n")
            w.writerow(["pose", "bias_mm", "distance_m", "spec_mm", "within_spec", "n_pixels"])
            for p, d in self.depth_bias.items():
                w.writerow([p, f"{d['bias_mm']:.2f}", f"{d['distance_m']:.3f}", f"{d['spec_mm']:.2f}",
                            d["within_spec"], d["n_pixels"]])
            out["depth_bias"] = buf.getvalue()
        return out

    def _uncertainty_csv(self) -> str:
        """One row per camera parameter: value and standard error; then each camera's projection
        uncertainty (median and worst over the image, px; mrcal's figure, the worst over the
        working band, as the limits judge it), the lens model's alone, the camera's in the rig,
        mrcal's figure at the working distance and at other multiples of it."""
        buf = io.StringIO()
        w = csv.writer(buf, lineterminator="\n")
        w.writerow(["camera", "parameter", "value", "std", "unit"])
        for c, u in self.uncertainty.items():
            vals = u.get("values", {})
            for k, sd in u.get("std", {}).items():
                unit = ("deg" if k == "rotation_deg" else "mm" if k == "translation_mm"
                        else "px" if k in ("fx", "fy", "cx", "cy") else "")
                v = vals.get(k)
                w.writerow([c, k, "" if v is None else f"{v:.6g}", f"{sd:.4g}" if sd > 0 else "fixed", unit])
            ps = u.get("projection_sigma_px", {})
            for k in ("median", "worst", "worst_where_seen", "lens_alone_median", "lens_alone_worst",
                      "rig_median", "rig_worst", "among_boards_median"):
                if ps.get(k) is not None:
                    w.writerow([c, f"projection_sigma_{k}", "", f"{ps[k]:.4g}", "px"])
            for f, v in (ps.get("among_boards_median_by_distance") or {}).items():
                w.writerow([c, f"projection_sigma_among_boards_median_at_{f}", "", f"{v:.4g}", "px"])
            w.writerow([c, "working_distance", f"{u.get('working_distance_m', float('nan')):.4g}", "", "m"])
            for k, v in zip(("working_band_near", "working_band_far"), u.get("working_band_m") or ()):
                w.writerow([c, k, f"{v:.4g}", "", "m"])
            if u.get("board_plane_spread_deg") is not None:
                w.writerow([c, "board_plane_spread", f"{u['board_plane_spread_deg']:.3g}", "", "deg"])
            lm = u.get("lens_model", {})
            if lm:
                w.writerow([c, "lens_model", lm.get("model", ""), "", ""])
        return buf.getvalue()

    def write_csv(self, folder: str | Path, prefix: str = "") -> list[Path]:
        """Write the tables as ``<prefix><table>.csv`` into ``folder`` (atomically); returns the paths."""
        folder = Path(folder)
        paths = []
        for name, text in self.csv_tables().items():
            p = folder / f"{prefix}{name}.csv"
            atomic_write_text(p, text)
            paths.append(p)
        return paths


def _fmt(e: dict[str, Any] | None, key: str) -> str:
    return "" if e is None else f"{e[key]:.4f}"


def _match(da: Detection, db: Detection) -> tuple[np.ndarray, np.ndarray]:
    """Indices into da.corners and db.corners of the same board corners."""
    if da.ids is None and db.ids is None:
        n = min(len(da.corners), len(db.corners))
        idx = np.arange(n)
        return idx, idx
    ia = da.ids if da.ids is not None else np.arange(len(da.corners))
    ib = db.ids if db.ids is not None else np.arange(len(db.corners))
    common, xa, xb = np.intersect1d(ia, ib, return_indices=True)
    return xa, xb


def epipolar_distances(cal: Calibration, origin: str, target: str, uv_o: np.ndarray, uv_t: np.ndarray) -> np.ndarray:
    """Distances (N,) of the target's points ``uv_t`` (N, 2) to the epipolar lines of the origin's
    points ``uv_o`` (N, 2), in the target's undistorted pixel units."""
    co, ct = cal.rig.camera(origin), cal.rig.camera(target)
    R = ct.R_cam_rig @ co.R_cam_rig.T
    t = ct.t_cam_rig - R @ co.t_cam_rig
    tx = np.array([[0, -t[2], t[1]], [t[2], 0, -t[0]], [-t[1], t[0], 0]])
    E = tx @ R
    xo = np.c_[co.undistort_normalized(uv_o), np.ones(len(uv_o))]
    xt = np.c_[ct.undistort_normalized(uv_t), np.ones(len(uv_t))]
    lines = xo @ E.T                      # in target normalised coordinates
    lines_px = lines @ np.linalg.inv(ct.K)  # K^-T l, row-wise
    pt = xt @ ct.K.T
    return np.abs(np.sum(lines_px * pt, axis=1)) / np.linalg.norm(lines_px[:, :2], axis=1)


def _board_roi(cal: Calibration, pose: str, margin: float = 0.05) -> tuple[np.ndarray, np.ndarray]:
    """A box around the whole board (with its paper margin) in the rig frame, for meshing."""
    b = cal.board
    R, t = cal.board_poses[pose]
    s = b.square_size
    corners = np.array([[-2 * s, -2 * s, 0], [(b.columns + 1) * s, -2 * s, 0],
                        [(b.columns + 1) * s, (b.rows + 1) * s, 0], [-2 * s, (b.rows + 1) * s, 0]])
    X = corners @ R.T + t
    return X.min(axis=0) - margin, X.max(axis=0) + margin


def tof_bias(cal: Calibration, det: Detection, depth_m: np.ndarray, pose: str) -> dict[str, Any] | None:
    """Median (measured - calibrated plane) z in mm inside the detected corners of the depth camera."""
    cam = cal.rig.depth()
    if det.corners is None or len(det.corners) < 4 or pose not in cal.board_poses:
        return None
    mask = np.zeros(depth_m.shape, np.uint8)
    hull = cv2.convexHull(det.corners.reshape(-1, 1, 2).astype(np.float32))
    cv2.fillConvexPoly(mask, np.round(hull).astype(np.int32), 1)
    v, u = np.nonzero(mask & np.isfinite(depth_m))
    if len(u) < 20:
        return None
    R_rb, t_rb = cal.board_poses[pose]
    R = cam.R_cam_rig @ R_rb
    t = cam.R_cam_rig @ t_rb + cam.t_cam_rig
    n = R[:, 2]
    d = cam.rays_cam(np.c_[u, v].astype(np.float64))  # z = 1
    z_plane = float(n @ t) / (d @ n)
    diff_mm = (depth_m[v, u].astype(np.float64) - z_plane) * 1000.0
    dist = float(np.median(z_plane))
    bias = float(np.median(diff_mm))
    spec = TOF_SPEC_MM + TOF_SPEC_REL * dist * 1000.0
    return {"bias_mm": bias, "distance_m": dist, "spec_mm": spec, "within_spec": bool(abs(bias) < spec),
            "n_pixels": int(len(u)), "spread_mm": float(np.percentile(diff_mm, 84) - np.percentile(diff_mm, 16)) / 2}


def error_tables(session: Session, calibration: Calibration, detections: dict[tuple[str, str], Detection],
                 excluded: set[tuple[str, str]] | frozenset = frozenset(), progress: Reporter | None = None,
                 roi: tuple[np.ndarray, np.ndarray] | None = None) -> CalibrationReport:
    """Compute the three tables (see the module docstring) over the found, not excluded views.
    ``roi`` (min (3,), max (3,)) in the rig frame overrides the per-pose box around the board
    used to mesh the depth maps."""
    from ..registration.params import RegistrationParams
    from ..registration.transport import transport_pixels

    progress = ensure_reporter(progress)
    cal = calibration
    cams = list(session.cameras)
    # a symmetric board's views in the corner order the calibration settled on
    views = oriented_views(usable_views(session, detections, excluded), getattr(cal, "flipped", set()))
    norm = {c: cal.rig.camera(c).normalization for c in cams}

    # intrinsic
    intrinsic, v_intr = {}, {}
    with progress.stage("intrinsic errors", 0.0):
        for c in cams:
            cc = cal.intrinsics[c]
            init = {p: cal.view_board_cam[(p, c)] for p in views[c] if (p, c) in cal.view_board_cam}
            per_view, _poses, resid, _rms = _per_view_errors(cc.K, cc.dist, views[c], cal.board, init)
            intrinsic[c] = _cell([np.linalg.norm(r, axis=1) for r in resid.values()], norm[c])
            v_intr[c] = dict(sorted(per_view.items()))
    progress(0.1, "extrinsic (epipolar) errors")

    # extrinsic (epipolar)
    extrinsic: dict[str, dict[str, Any]] = {}
    v_ext: dict[str, dict[str, dict[str, float]]] = {}
    for o in cams:
        extrinsic[o], v_ext[o] = {}, {}
        for t in cams:
            if o == t:
                continue
            vals, per = [], {}
            for p in sorted(set(views[o]) & set(views[t])):
                io_, it_ = _match(views[o][p], views[t][p])
                if len(io_) == 0:
                    continue
                d = epipolar_distances(cal, o, t, views[o][p].corners[io_], views[t][p].corners[it_])
                vals.append(d)
                per[p] = float(np.mean(d))
            extrinsic[o][t] = _cell(vals, norm[t])
            v_ext[o][t] = per
    progress(0.2, "depth errors")

    # depth
    depth = None
    v_depth: dict[str, Any] = {}
    bias_mm: dict[str, float] = {}
    bias: dict[str, dict[str, Any]] = {}
    warn: list[str] = []
    if session.depth_camera is not None:
        dcam = session.depth_camera
        acc: dict[str, dict[str, list[np.ndarray]]] = {o: {t: [] for t in cams if t != o} for o in cams}
        v_depth = {o: {t: {} for t in cams if t != o} for o in cams}
        poses = [p for p in session.poses if p.depth is not None]
        for k, pose in enumerate(poses):
            progress(0.2 + 0.8 * k / max(1, len(poses)), f"depth errors {pose.name}")
            seen = [c for c in cams if pose.name in views[c]]
            if not seen or pose.name not in cal.board_poses:
                continue
            raw = read_image(pose.depth)
            if raw.ndim != 2:
                raise InputError(f"depth map must be single-channel, got shape {raw.shape}", pose.depth)
            dc = cal.rig.camera(dcam)
            if raw.shape != dc.shape:
                raise InputError(f"depth map is {raw.shape[1]}x{raw.shape[0]} but depth camera '{dcam}' is "
                                 f"{dc.width}x{dc.height}", pose.depth)
            depth_m = raw.astype(np.float32) * np.float32(session.depth_scale)
            depth_m[~(depth_m > 0)] = np.nan
            if not np.isfinite(depth_m).any():
                warn.append(f"{pose.depth}: depth map has no valid pixel (all 0 or NaN): no depth errors for "
                            f"pose {pose.name}")
                continue
            if pose.name in views[dcam]:
                b = tof_bias(cal, views[dcam][pose.name], depth_m, pose.name)
                if b is not None:
                    bias[pose.name] = b
                    bias_mm[pose.name] = b["bias_mm"]
            if len(seen) < 2:
                continue
            lo, hi = roi if roi is not None else _board_roi(cal, pose.name)
            params = RegistrationParams(roi_min=np.asarray(lo, float), roi_max=np.asarray(hi, float))
            for o in seen:
                for t in seen:
                    if o == t:
                        continue
                    io_, it_ = _match(views[o][pose.name], views[t][pose.name])
                    if len(io_) == 0:
                        continue
                    uv = transport_pixels(cal.rig, depth_m, o, views[o][pose.name].corners[io_].astype(np.float64), t, params)
                    d = np.linalg.norm(uv - views[t][pose.name].corners[it_], axis=1)
                    if np.isfinite(d).any():
                        acc[o][t].append(d)
                        v_depth[o][t][pose.name] = float(np.nanmean(d))
        depth = {o: {t: _cell(acc[o][t], norm[t]) for t in acc[o]} for o in cams}
    progress(1.0, "error tables done")

    cameras = {c: {"width": cal.rig.camera(c).width, "height": cal.rig.camera(c).height,
                   "normalization": norm[c], "modality": session.cameras[c]} for c in cams}
    weak = [{"pose": p, "camera": c, "px": e, "reason": r} for p, c, e, r in cal.weak_views]
    return CalibrationReport(intrinsic, extrinsic, depth, {"intrinsic": v_intr, "extrinsic": v_ext, "depth": v_depth},
                             bias_mm, bias, cameras, weak, sorted(view_key(p, c) for p, c in excluded), warnings=warn,
                             uncertainty=uncertainty_dict(cal),
                             accepted_uncertain=list(getattr(cal, "accepted_uncertain", [])))


def uncertainty_dict(cal: Calibration) -> dict[str, dict[str, Any]]:
    """camera -> its uncertainty (:meth:`~.uncertainty.CameraUncertainty.to_dict`) with the
    parameter values beside their standard errors and the lens model choice."""
    out = {}
    for c, u in getattr(cal, "uncertainty", {}).items():
        d = u.to_dict()
        cc = cal.intrinsics[c]
        cam = cal.rig.camera(c)
        vals = {"fx": cc.K[0, 0], "fy": cc.K[1, 1], "cx": cc.K[0, 2], "cy": cc.K[1, 2]}
        for k, v in zip(("k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6"), cc.dist):
            vals[k] = float(v)
        if c != cal.reference:
            from .calibrate import _angle_deg

            vals["rotation_deg"] = _angle_deg(cam.R_cam_rig)
            vals["translation_mm"] = float(1000 * np.linalg.norm(cam.t_cam_rig))
        d["values"] = {k: float(v) for k, v in vals.items()}
        d["lens_model"] = cc.lens_model_dict()
        out[c] = d
    return out


def empty_depth_maps(session: Session) -> tuple[list, list]:
    """(empty, all) depth-map paths of the session's poses; empty = no pixel > 0 (all 0 or NaN).
    Cheap (depth maps are small), so a command can check them before any calibration work."""
    empty, every = [], []
    for pose in session.poses:
        if pose.depth is None:
            continue
        every.append(pose.depth)
        raw = read_image(pose.depth)
        with np.errstate(invalid="ignore"):
            if not np.any(np.asarray(raw, dtype=np.float64) > 0):
                empty.append(pose.depth)
    return empty, every
