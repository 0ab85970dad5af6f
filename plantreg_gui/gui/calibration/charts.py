"""Matplotlib charts of the wizard: per-view reprojection error bars, ToF bias per pose.

Like MATLAB's Camera Calibrator: one bar per view, the mean as a dashed line, weak views in
orange; clicking a bar emits ``bar_clicked(camera, pose)`` so the wizard can open that view.
"""

from __future__ import annotations

import math

import numpy as np
from matplotlib.backends.backend_qtagg import FigureCanvasQTAgg
from matplotlib.figure import Figure
from PySide6.QtCore import QPointF, Signal
from PySide6.QtWidgets import QSizePolicy

NORMAL = "#4c72b0"
WEAK = "#e8702a"
SELECTED = "#c0392b"


class _Canvas(FigureCanvasQTAgg):
    def __init__(self, parent=None, height: float = 3.0) -> None:
        self.figure = Figure(figsize=(6, height), dpi=90, layout="constrained")
        super().__init__(self.figure)
        self.setParent(parent)
        self.setSizePolicy(QSizePolicy.Policy.Expanding, QSizePolicy.Policy.Expanding)
        self.setMinimumHeight(160)


class PerViewChart(_Canvas):
    """Per-view mean reprojection error (px), one subplot per camera."""

    bar_clicked = Signal(str, str)  # camera, pose

    def __init__(self, parent=None) -> None:
        super().__init__(parent)
        self.bars: dict[str, dict[str, float]] = {}
        self._rects: dict[tuple[str, str], object] = {}
        self._axes: dict[str, object] = {}
        self.mpl_connect("pick_event", self._on_pick)
        self.set_data({}, {}, {})

    def set_data(self, per_view: dict[str, dict[str, float]], weak: dict[str, set[str]],
                 mean: dict[str, float], selected: tuple[str, str] | None = None) -> None:
        """``per_view[cam][pose]`` px; ``weak[cam]`` poses flagged weak; ``mean[cam]`` px."""
        fig = self.figure
        fig.clear()
        self.bars = {c: dict(v) for c, v in per_view.items()}
        self._rects.clear()
        self._axes.clear()
        cams = [c for c in per_view if per_view[c]]
        if not cams:
            ax = fig.add_subplot(111)
            ax.text(0.5, 0.5, "No calibration yet", ha="center", va="center", transform=ax.transAxes,
                    color="#666666")
            ax.set_axis_off()
            self.draw_idle()
            return
        ncol = 1 if len(cams) <= 2 else 2
        nrow = math.ceil(len(cams) / ncol)
        for k, cam in enumerate(cams):
            ax = fig.add_subplot(nrow, ncol, k + 1)
            self._axes[cam] = ax
            poses = sorted(per_view[cam])
            vals = [float(per_view[cam][p]) for p in poses]
            colours = []
            for p in poses:
                if selected == (cam, p):
                    colours.append(SELECTED)
                elif p in weak.get(cam, set()):
                    colours.append(WEAK)
                else:
                    colours.append(NORMAL)
            rects = ax.bar(range(len(poses)), vals, color=colours, edgecolor="black", linewidth=0.4, picker=True)
            for p, r in zip(poses, rects):
                r.set_gid(f"{cam}\x1f{p}")
                self._rects[(cam, p)] = r
            m = mean.get(cam)
            title = f"{cam}: per-view reprojection error"
            if m is not None and math.isfinite(m):
                ax.axhline(m, color="#333333", linestyle="--", linewidth=1.0)
                title += f" (dashed: mean {m:.3f} px)"
            n_weak = sum(1 for p in poses if p in weak.get(cam, set()))
            if n_weak:
                title += f", {n_weak} weak"
            ax.set_title(title, fontsize=9)
            ax.set_ylabel("px", fontsize=8)
            ax.set_xticks(range(len(poses)))
            short = [p.replace("pose_", "") for p in poses]
            ax.set_xticklabels(short, rotation=90 if len(poses) > 12 else 0, fontsize=7)
            ax.tick_params(axis="y", labelsize=7)
            ax.set_ylim(0, max(vals + [m or 0]) * 1.18 if vals else 1)
            ax.margins(x=0.01)
        self.draw_idle()

    def tallest(self, camera: str) -> str | None:
        v = self.bars.get(camera) or {}
        return max(v, key=v.get) if v else None

    def bar_center(self, camera: str, pose: str) -> QPointF:
        """Widget coordinates of the middle of a bar (for tests and keyboard access)."""
        self.draw()
        r = self._rects[(camera, pose)]
        x = r.get_x() + r.get_width() / 2
        y = r.get_height() / 2
        X, Y = r.axes.transData.transform((x, y))
        dpr = self.devicePixelRatioF() or 1.0
        return QPointF(X / dpr, self.height() - Y / dpr)

    def _on_pick(self, event) -> None:
        gid = event.artist.get_gid() if event.artist is not None else None
        if gid and "\x1f" in gid:
            cam, pose = gid.split("\x1f", 1)
            self.bar_clicked.emit(cam, pose)


class BiasChart(_Canvas):
    """ToF depth bias per pose (mm) with the Azure Kinect specification band."""

    def __init__(self, parent=None) -> None:
        super().__init__(parent, height=2.6)
        self.set_data({}, {})

    def set_data(self, bias_mm: dict[str, float], distance_mm: dict[str, float]) -> None:
        fig = self.figure
        fig.clear()
        ax = fig.add_subplot(111)
        poses = sorted(p for p, v in bias_mm.items() if v is not None and np.isfinite(v))
        if not poses:
            ax.text(0.5, 0.5, "No depth bias (the rig has no depth camera or no depth maps)", ha="center",
                    va="center", transform=ax.transAxes, color="#666666")
            ax.set_axis_off()
            self.draw_idle()
            return
        vals = np.array([bias_mm[p] for p in poses], float)
        spec = np.array([11.0 + 0.001 * distance_mm.get(p, float("nan")) for p in poses])
        x = np.arange(len(poses))
        over = np.abs(vals) > np.nan_to_num(spec, nan=11.0)
        ax.bar(x, vals, color=np.where(over, WEAK, NORMAL), edgecolor="black", linewidth=0.4)
        if np.isfinite(spec).any():
            ax.step(np.r_[x - 0.5, x[-1] + 0.5], np.r_[spec, spec[-1]], where="post", color="#c0392b",
                    linestyle="--", linewidth=1.0, label="Azure Kinect spec ±(11 mm + 0.1 % of distance)")
            ax.step(np.r_[x - 0.5, x[-1] + 0.5], -np.r_[spec, spec[-1]], where="post", color="#c0392b",
                    linestyle="--", linewidth=1.0)
        else:
            ax.axhline(11, color="#c0392b", linestyle="--", linewidth=1.0, label="Azure Kinect spec ±11 mm")
            ax.axhline(-11, color="#c0392b", linestyle="--", linewidth=1.0)
        ax.axhline(0, color="black", linewidth=0.6)
        ax.set_xticks(x)
        ax.set_xticklabels([p.replace("pose_", "") for p in poses], fontsize=7,
                           rotation=90 if len(poses) > 12 else 0)
        ax.set_ylabel("bias (mm)", fontsize=8)
        ax.set_title("ToF bias per pose: measured depth on the board minus the calibrated board plane",
                     fontsize=9)
        ax.tick_params(axis="y", labelsize=7)
        lim = max(float(np.nanmax(np.abs(vals))), float(np.nanmax(spec)) if np.isfinite(spec).any() else 11.0)
        ax.set_ylim(-1.25 * lim, 1.25 * lim)
        ax.legend(fontsize=7, loc="upper right")
        self.draw_idle()
