"""Read-outs of the engine's results for display (the one place that knows their structure)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

Key = tuple[str, str]


def camera_names(cal, session) -> list[str]:
    if cal is not None:
        return list(cal.rig.names)
    return list(session.camera_names) if session is not None else []


def intrinsic_rows(cal, report=None) -> list[dict[str, Any]]:
    """Per camera: fx, fy, cx, cy, dist, px (mean corner distance), normalized, views, weak, std
    (parameter -> standard error), sigma (median, worst projection uncertainty px), model (label),
    model_reason, model_cv (candidate -> cross-validated px)."""
    rows = []
    intr_tab = _get(report, "intrinsic") if report is not None else None
    for name, c in cal.intrinsics.items():
        K = np.asarray(c.K)
        px = float(c.mean_px)
        nn = px * float(c.normalization)
        if isinstance(intr_tab, dict) and isinstance(intr_tab.get(name), dict):
            px = float(intr_tab[name].get("px", px))
            nn = float(intr_tab[name].get("normalized", nn))
        u = uncertainty(cal).get(name)
        lm = c.lens_model_dict() if hasattr(c, "lens_model_dict") else {}
        rows.append({"camera": name, "fx": float(K[0, 0]), "fy": float(K[1, 1]), "cx": float(K[0, 2]),
                     "cy": float(K[1, 2]), "dist": [float(d) for d in np.ravel(c.dist)], "px": px,
                     "normalized": nn, "rms": float(c.rms_px), "views": int(c.n_views or len(c.per_view_px)),
                     "weak": [p for p, _e, _r in c.weak_views],
                     "std": dict(u.std) if u is not None else {},
                     "sigma": u.summary() if u is not None else None,
                     "model": lm.get("label", lm.get("model", "")), "model_reason": lm.get("reason", ""),
                     "model_cv": lm.get("cv_rms_px", {})})
    return rows


def per_view_px(cal) -> dict[str, dict[str, float]]:
    return {name: {p: float(v) for p, v in c.per_view_px.items()} for name, c in cal.intrinsics.items()}


def excluded_px(cal, excluded, detections) -> dict[str, dict[str, float]]:
    """cam -> pose -> px of the excluded views whose board was found: the calibration's measure
    of them (``excluded_px``, or ``per_view_px`` if they were excluded after it ran), else nan."""
    out: dict[str, dict[str, float]] = {}
    for pose, cam in excluded:
        d = detections.get((pose, cam))
        if d is None or getattr(d, "status", None) != "found":
            continue
        v = getattr(cal, "excluded_px", {}).get((pose, cam))
        if v is None and cam in cal.intrinsics:
            v = cal.intrinsics[cam].per_view_px.get(pose)
        out.setdefault(cam, {})[pose] = float("nan") if v is None else float(v)
    return out


def weak_by_camera(cal) -> dict[str, set[str]]:
    return {name: {p for p, _e, _r in c.weak_views} for name, c in cal.intrinsics.items()}


def weak_views(cal) -> set[Key]:
    if cal is None:
        return set()
    return {(p, name) for name, c in cal.intrinsics.items() for p, _e, _r in c.weak_views}


def board_outlines(cal, session) -> list[np.ndarray]:
    """Rig-frame outlines (4, 3) of the printed pattern in every calibrated board pose."""
    b = cal.board
    s = b.square_size
    corners = np.array([[-s, -s, 0], [b.columns * s, -s, 0], [b.columns * s, b.rows * s, 0], [-s, b.rows * s, 0]])
    out = []
    for _pose, (R, t) in sorted(cal.board_poses.items()):
        out.append(corners @ np.asarray(R).T + np.asarray(t).reshape(3))
    return out


def board_distance_mm(cal) -> dict[str, float]:
    """Distance (mm) from the depth camera (rig origin) to the board centre, per pose."""
    if cal is None:
        return {}
    b = cal.board
    c = np.array([(b.columns - 1) * b.square_size / 2, (b.rows - 1) * b.square_size / 2, 0.0])
    return {p: float(np.linalg.norm(np.asarray(R) @ c + np.asarray(t).reshape(3)) * 1000)
            for p, (R, t) in cal.board_poses.items()}


def _get(obj, name: str):
    if obj is None:
        return None
    if isinstance(obj, dict):
        return obj.get(name)
    return getattr(obj, name, None)


def table(report, which: str) -> dict:
    """``report.<which>`` as {origin: {target: {"px", "normalized"}}} ({} if absent)."""
    t = _get(report, which)
    return t if isinstance(t, dict) else {}


def max_cell(tab: dict) -> tuple[str, str, float] | None:
    best = None
    for o, row in (tab or {}).items():
        for t, c in (row or {}).items():
            if o == t or not isinstance(c, dict):
                continue
            v = c.get("px")
            if v is not None and math.isfinite(float(v)) and (best is None or float(v) > best[2]):
                best = (o, t, float(v))
    return best


def _norm(report, camera: str) -> float:
    cams = _get(report, "cameras") or {}
    try:
        return float(cams[camera]["normalization"])
    except (KeyError, TypeError, ValueError):
        return float("nan")


def bias_distance_mm(report) -> dict[str, float]:
    """Board distance (mm) per pose as the engine measured it for the ToF bias."""
    d = _get(report, "depth_bias") or {}
    out = {}
    for p, v in d.items():
        try:
            out[str(p)] = float(v["distance_m"]) * 1000.0
        except (KeyError, TypeError, ValueError):
            continue
    return out


def depth_bias(report) -> dict[str, float]:
    d = _get(report, "depth_bias_mm")
    return {str(k): float(v) for k, v in d.items() if v is not None} if isinstance(d, dict) else {}


def depth_views(report) -> tuple[list[tuple[str, dict]], list[tuple[str, str]]]:
    """Per-view depth errors: rows [(pose, {(origin, target): {"px", "normalized"}})] worst first,
    and the (origin, target) pairs present."""
    views = _get(report, "views")
    rows: dict[str, dict] = {}
    if isinstance(views, dict):
        dv = views.get("depth")
        if isinstance(dv, dict):
            for o, row in dv.items():
                for t, per_pose in (row or {}).items():
                    if isinstance(per_pose, dict):
                        for pose, c in per_pose.items():
                            if isinstance(c, dict):
                                rows.setdefault(pose, {})[(o, t)] = c
                            elif c is not None:
                                nrm = _norm(report, t)
                                rows.setdefault(pose, {})[(o, t)] = {"px": float(c), "normalized": float(c) * nrm}
    pairs = sorted({pr for v in rows.values() for pr in v})

    def worst(item):
        vals = [c.get("px") for c in item[1].values() if c.get("px") is not None]
        return -max(vals) if vals else 0.0

    return sorted(rows.items(), key=worst), pairs


def uncertainty(cal) -> dict[str, Any]:
    """camera -> the calibration's :class:`~plantreg_gui.core.calibration.uncertainty.CameraUncertainty` ({} if none)."""
    return dict(getattr(cal, "uncertainty", {}) or {}) if cal is not None else {}


def uncertainty_problems(cal) -> list[str]:
    """The limits the calibration exceeds (one sentence each); [] if none or not calibrated."""
    return list(cal.uncertainty_problems()) if cal is not None and hasattr(cal, "uncertainty_problems") else []


def pm(value: float, std: float | None, digits: int = 2) -> str:
    """``value ± std`` (``value (fixed)`` for a held parameter, just the value without a std)."""
    if std is None or not math.isfinite(std):
        return f"{value:.{digits}f}"
    if std == 0:
        return f"{value:.{digits}f} (fixed)"
    return f"{value:.{digits}f} ± {std:.{digits}f}"


def uncertainty_maps(cal) -> list[dict[str, Any]]:
    """Per camera, what the heat map draws: sigma grid (px), corners per cell, the camera's limit
    (median limit, px), the image aspect and a title with the summary and where to add views."""
    from ...core.calibration.uncertainty import limits_px

    out = []
    for name, u in uncertainty(cal).items():
        med, worst = u.summary()
        lim, lim_seen = limits_px(u)
        lo, hi = u.band_m
        # short titles (four panels share ~400 px at 1280 x 720): the least certain regions of a
        # camera within its limits go to the tooltip ("detail"); where to add views stays. Each
        # figure beside its own limit: "worst 1.93 px (limit 1.72) ... within the limits" read as
        # a contradiction (the limit was the median's; the worst is judged only where boards were seen)
        where = f"add views: {', '.join(u.add_views)}" if u.needs_views else "within the limits"
        title = f"{name}: σ median {med:.2f} (limit {lim:.2f}), seen worst {u.covered_worst:.2f} px\nat {lo:.2f}-{hi:.2f} m: {where}"
        detail = (f"{name}: worst where boards were seen {u.covered_worst:.2f} px (limit {lim_seen:.2f}); "
                  f"{worst:.2f} px over the whole image, hatched cells included (not judged)"
                  + (f"; least certain {', '.join(u.add_views)}" if not u.needs_views and u.add_views else ""))
        out.append({"camera": name, "sigma": u.judged, "corners": u.corners, "limit": lim,
                    "needs_views": u.needs_views,
                    "aspect": u.width / max(u.height, 1), "title": title, "detail": detail})
    return out


def red_cells_note(report, cal=None, red: float = 3.0) -> str:
    """What the red cells of the extrinsic (epipolar) table say, and what may make them red;
    "" when no cell's normalised error reaches ``red``. Names each red cell (origin -> target, px,
    normalised, its worst views), the target image's size (a fraction of a pixel is red on a
    small thermal image), the usual causes, and, with ``cal``, a camera whose corners fit the
    joint rig much worse than its own lens model (views that disagree with one rigid rig)."""
    tab = table(report, "extrinsic")
    cams = _get(report, "cameras") or {}
    per_view = (_get(report, "views") or {}).get("extrinsic") or {}
    cells = []
    for o, row in tab.items():
        for t, c in (row or {}).items():
            if o == t or not isinstance(c, dict):
                continue
            nn, px = c.get("normalized"), c.get("px")
            if nn is not None and px is not None and math.isfinite(float(nn)) and float(nn) >= red:
                cells.append((float(nn), o, t, float(px)))
    if not cells:
        return ""
    cells.sort(reverse=True)
    parts = []
    for nn, o, t, px in cells:
        views = (per_view.get(o) or {}).get(t) or {}
        vals = {p: float(v["px"] if isinstance(v, dict) else v) for p, v in views.items()
                if v is not None and (not isinstance(v, dict) or v.get("px") is not None)}
        worst = sorted(vals, key=vals.get, reverse=True)[:3]
        size = cams.get(t) or {}
        wh = f" of {t}'s {size['width']} × {size['height']}" if "width" in size and "height" in size else ""
        parts.append(f"{o} → {t} {px:.2f} px{wh} = {nn:.2f} normalised"
                     + (f" (worst views {', '.join(worst)})" if worst else ""))
    text = (f"Red cells (normalised error ≥ {red:g}): " + "; ".join(parts) + ". Red means that the origin "
            f"camera's corners, carried through the calibrated rig, miss the target camera's corners by more "
            f"than {red:g} px per 1000 px of the target image's size: on a small image a fraction of a pixel is "
            "already red. Usual causes: the cameras did not see the board at the same moment (a hand-held "
            "board, cameras not triggered together), a camera moved between views, or mislocated corners "
            "(look at the worst views on page 3).")
    if cal is not None:
        noise = getattr(cal, "noise_px", {}) or {}
        for name in sorted({c for _nn, o, t, _px in cells for c in (o, t)}):
            own = getattr(cal.intrinsics.get(name), "rms_px", None) if name in cal.intrinsics else None
            joint = noise.get(name)
            if own is None or joint is None or not own > 0:
                continue
            own_coord = float(own) / math.sqrt(2.0)  # the lens fit's RMS corner distance, per coordinate
            if joint >= 2.0 * own_coord:
                text += (f" {name}'s corners fit the joint rig {joint / own_coord:.1f} × worse than its own lens "
                         f"model ({joint:.2f} against {own_coord:.2f} px per coordinate): its views disagree "
                         "with one rigid rig, as when the board moves between the cameras' exposures.")
    return text
