"""Bar charts of the wizard: per-view reprojection error bars, ToF bias per pose.

Like MATLAB's Camera Calibrator: one bar per view, the mean as a dashed line, weak views in
orange; views excluded from the calibration stay on the chart, hatched grey and marked ✖ (their
error measured with the final intrinsics), so a rejection leaves a trace. Clicking a bar emits
``bar_clicked(camera, pose)`` so the wizard can open that view.

Drawn with QPainter: these charts are redrawn whenever a calibration arrives, and Matplotlib
took 0.5-1 s of GUI-thread time for four panels of twenty bars (constrained layout, text
measuring); painting them takes a few milliseconds.
"""

from __future__ import annotations

import math

import numpy as np
from PySide6.QtCore import QPointF, QRect, QRectF, Qt, Signal
from PySide6.QtGui import QBrush, QColor, QFont, QFontMetricsF, QPainter, QPen
from PySide6.QtWidgets import QSizePolicy, QWidget

NORMAL = "#4c72b0"
WEAK = "#e8702a"
SELECTED = "#c0392b"
EXCLUDED = "#9a9a9a"


def nice_ticks(hi: float, lo: float = 0.0, n: int = 5) -> np.ndarray:
    """About ``n`` round tick values covering [lo, hi] (1, 2, 5 x 10^k steps)."""
    span = max(hi - lo, 1e-12)
    raw = span / max(n, 1)
    mag = 10 ** math.floor(math.log10(raw))
    step = next(m * mag for m in (1, 2, 5, 10) if m * mag >= raw)
    return np.arange(math.floor(lo / step) * step, hi + step * 0.5, step)


def _fmt_tick(v: float) -> str:
    return f"{v:.3g}" if abs(v) >= 1e-9 else "0"


class _Panel:
    """One axes: a rectangle in widget coordinates, bars at x = 0..n-1, a y range."""

    def __init__(self, rect: QRectF, n: int, ylo: float, yhi: float) -> None:
        self.rect, self.n, self.ylo, self.yhi = rect, max(n, 1), ylo, yhi

    def x(self, i: float) -> float:
        return self.rect.left() + (i + 0.5) * self.rect.width() / self.n

    def y(self, v: float) -> float:
        return self.rect.bottom() - (v - self.ylo) / max(self.yhi - self.ylo, 1e-12) * self.rect.height()

    @property
    def bar_w(self) -> float:
        return 0.8 * self.rect.width() / self.n


def _draw_axes(p: QPainter, panel: _Panel, title: str, ylabel: str, xlabels: list[str], small: QFont) -> None:
    r = panel.rect
    p.setPen(QPen(QColor("#333333"), 1))
    p.setFont(small)
    fm = p.fontMetrics()
    for v in nice_ticks(panel.yhi, panel.ylo):
        if v < panel.ylo - 1e-12 or v > panel.yhi + 1e-12:
            continue
        y = panel.y(v)
        p.setPen(QPen(QColor("#e6e6e6"), 1))
        p.drawLine(QPointF(r.left(), y), QPointF(r.right(), y))
        p.setPen(QPen(QColor("#333333"), 1))
        p.drawLine(QPointF(r.left() - 3, y), QPointF(r.left(), y))
        s = _fmt_tick(v)
        p.drawText(QPointF(r.left() - 5 - fm.horizontalAdvance(s), y + fm.ascent() / 2 - 1), s)
    p.setBrush(Qt.BrushStyle.NoBrush)  # the frame only: the brush is left from the previous panel's bars
    p.drawRect(r)
    # every step-th label, so that the longest (pose names may be time stamps) do not overlap
    lw = max((fm.horizontalAdvance(s) for s in xlabels), default=0) + 8
    step = max(1, math.ceil(len(xlabels) * lw / max(r.width(), 1)))
    for i, s in enumerate(xlabels):
        if i % step == 0:
            p.drawText(QPointF(panel.x(i) - fm.horizontalAdvance(s) / 2, r.bottom() + fm.ascent() + 2), s)
    p.save()
    p.translate(r.left() - 36, r.center().y())
    p.rotate(-90)
    p.drawText(QPointF(-fm.horizontalAdvance(ylabel) / 2, 0), ylabel)
    p.restore()
    if title:
        tf = QFont(small)
        tf.setBold(True)
        p.setFont(tf)
        p.drawText(QRectF(r.left(), r.top() - fm.height() - 4, r.width(), fm.height() + 2),
                   Qt.AlignmentFlag.AlignCenter | Qt.TextFlag.TextSingleLine, title)
        p.setFont(small)


class _Chart(QWidget):
    def __init__(self, parent=None, min_height: int = 160) -> None:
        super().__init__(parent)
        self.setSizePolicy(QSizePolicy.Policy.Expanding, QSizePolicy.Policy.Expanding)
        self.setMinimumHeight(min_height)
        self.setAutoFillBackground(True)
        pal = self.palette()
        pal.setColor(self.backgroundRole(), QColor("white"))
        self.setPalette(pal)

    def _small(self) -> QFont:
        f = QFont(self.font())
        f.setPointSizeF(max(7.0, self.font().pointSizeF() * 0.85))
        return f

    def _message(self, p: QPainter, text: str) -> None:
        p.setPen(QColor("#666666"))
        p.drawText(self.rect(), Qt.AlignmentFlag.AlignCenter | Qt.TextFlag.TextWordWrap, text)


class PerViewChart(_Chart):
    """Per-view mean reprojection error (px), one panel per camera; excluded views hatched."""

    bar_clicked = Signal(str, str)  # camera, pose

    def __init__(self, parent=None) -> None:
        super().__init__(parent)
        self.bars: dict[str, dict[str, float]] = {}  # used views: cam -> pose -> px
        self.excluded_bars: dict[str, dict[str, float]] = {}  # excluded views (nan: not measurable)
        self._weak: dict[str, set[str]] = {}
        self._mean: dict[str, float] = {}
        self._selected: tuple[str, str] | None = None
        self._rects: dict[tuple[str, str], QRectF] = {}

    def set_data(self, per_view: dict[str, dict[str, float]], weak: dict[str, set[str]],
                 mean: dict[str, float], selected: tuple[str, str] | None = None,
                 excluded: dict[str, dict[str, float]] | None = None) -> None:
        """``per_view[cam][pose]`` px; ``weak[cam]`` poses flagged weak; ``mean[cam]`` px;
        ``excluded[cam][pose]`` px (or nan) of views left out of the calibration."""
        self.bars = {c: dict(v) for c, v in per_view.items()}
        self.excluded_bars = {c: dict(v) for c, v in (excluded or {}).items() if v}
        self._weak = {c: set(v) for c, v in weak.items()}
        self._mean = dict(mean)
        self._selected = selected
        self._layout()
        self.update()

    def _cams(self) -> list[str]:
        return [c for c in list(self.bars) + [c for c in self.excluded_bars if c not in self.bars]
                if self.bars.get(c) or self.excluded_bars.get(c)]

    def _title(self, cam: str) -> str:
        used, ex = self.bars.get(cam, {}), self.excluded_bars.get(cam, {})
        weak = self._weak.get(cam, set())
        m = self._mean.get(cam)
        # short: with the uncertainty map beside it a panel is ~300 px wide
        title = f"{cam}: error per view"
        if m is not None and math.isfinite(m):
            title += f" (mean {m:.3f} px, dashed)"
        n_weak = sum(1 for q in used if q in weak)
        if n_weak:
            title += f", {n_weak} weak"
        if ex:
            title += f", {len(ex)} excluded ✖"
        return title

    def _title_font(self) -> QFont:
        f = self._small()
        f.setBold(True)
        return f

    def _layout(self) -> list[tuple[str, _Panel, list[str]]]:
        self._rects.clear()
        self._title_rects = {}
        cams = self._cams()
        out = []
        if not cams:
            return out
        ncol = 1 if len(cams) <= 2 else 2
        nrow = math.ceil(len(cams) / ncol)
        W, H = self.width(), self.height()
        cw, ch = W / ncol, H / nrow
        # a title wider than its cell wraps onto a second line over the whole cell (it was centred
        # on the plot area, one line, and its start was cut off at the widget's left edge)
        fm = QFontMetricsF(self._title_font())
        two = any(fm.horizontalAdvance(self._title(c)) > cw - 8 for c in cams)
        top_m = 2 * fm.lineSpacing() + 6 if two else 22
        for k, cam in enumerate(cams):
            i, j = divmod(k, ncol)
            used, ex = self.bars.get(cam, {}), self.excluded_bars.get(cam, {})
            poses = sorted(set(used) | set(ex))
            vals = [v for v in list(used.values()) + list(ex.values()) if math.isfinite(v)]
            top = max(vals + [self._mean.get(cam) or 0.0, 1e-3]) * 1.18
            rect = QRectF(j * cw + 52, i * ch + top_m, cw - 64, ch - top_m - 22)
            self._title_rects[cam] = QRectF(j * cw + 4, i * ch + 1, cw - 8, top_m - 4)
            panel = _Panel(rect, len(poses), 0.0, top)
            for n, pose in enumerate(poses):
                v = used.get(pose, ex.get(pose, float("nan")))
                h = v if math.isfinite(v) else top * 0.06  # an unmeasurable excluded view: a stub
                x0 = panel.x(n) - panel.bar_w / 2
                self._rects[(cam, pose)] = QRectF(x0, panel.y(h), panel.bar_w, panel.y(0) - panel.y(h))
            out.append((cam, panel, poses))
        return out

    def paintEvent(self, event) -> None:  # noqa: N802
        p = QPainter(self)
        p.setRenderHint(QPainter.RenderHint.Antialiasing, False)
        panels = self._layout()
        if not panels:
            self._message(p, "No calibration yet")
            return
        small = self._small()
        for cam, panel, poses in panels:
            used, ex = self.bars.get(cam, {}), self.excluded_bars.get(cam, {})
            weak = self._weak.get(cam, set())
            m = self._mean.get(cam)
            labels = [q.replace("pose_", "") for q in poses]
            _draw_axes(p, panel, "", "px", labels, small)
            p.setFont(self._title_font())
            p.drawText(self._title_rects[cam], Qt.AlignmentFlag.AlignHCenter | Qt.AlignmentFlag.AlignBottom
                       | Qt.TextFlag.TextWordWrap, self._title(cam))
            p.setFont(small)
            for pose in poses:
                r = self._rects[(cam, pose)]
                if pose in used:
                    colour = SELECTED if self._selected == (cam, pose) else (WEAK if pose in weak else NORMAL)
                    p.setBrush(QColor(colour))
                    p.setPen(QPen(QColor("black"), 0.6))
                    p.drawRect(r)
                else:
                    p.setBrush(QColor("#e4e4e4"))
                    p.setPen(QPen(QColor(EXCLUDED), 1, Qt.PenStyle.DashLine))
                    p.drawRect(r)
                    p.setBrush(QBrush(QColor(EXCLUDED), Qt.BrushStyle.BDiagPattern))
                    p.drawRect(r)
                    p.setPen(QColor("#b02a37"))
                    fm = p.fontMetrics()
                    p.drawText(QPointF(r.center().x() - fm.horizontalAdvance("✖") / 2, r.top() - 2), "✖")
            if m is not None and math.isfinite(m):
                p.setPen(QPen(QColor("#333333"), 1, Qt.PenStyle.DashLine))
                y = panel.y(m)
                p.drawLine(QPointF(panel.rect.left(), y), QPointF(panel.rect.right(), y))
        p.end()

    def resizeEvent(self, event) -> None:  # noqa: N802
        super().resizeEvent(event)
        self._layout()

    def tallest(self, camera: str) -> str | None:
        """The used view with the largest error (excluded views do not count)."""
        v = self.bars.get(camera) or {}
        return max(v, key=v.get) if v else None

    def bar_center(self, camera: str, pose: str) -> QPointF:
        """Widget coordinates of the middle of a bar (for tests and keyboard access)."""
        self._layout()
        return self._rects[(camera, pose)].center()

    def bar_at(self, pos: QPointF) -> tuple[str, str] | None:
        for key, r in self._rects.items():
            if r.adjusted(-1, -1, 1, 1).contains(pos):
                return key
        return None

    def mousePressEvent(self, event) -> None:  # noqa: N802
        key = self.bar_at(event.position())
        if key is not None and event.button() == Qt.MouseButton.LeftButton:
            self.bar_clicked.emit(key[0], key[1])
        super().mousePressEvent(event)


class BiasChart(_Chart):
    """ToF depth bias per pose (mm) with the Azure Kinect specification band."""

    def __init__(self, parent=None) -> None:
        super().__init__(parent, min_height=150)
        self.bias: dict[str, float] = {}
        self._dist: dict[str, float] = {}

    def set_data(self, bias_mm: dict[str, float], distance_mm: dict[str, float]) -> None:
        self.bias = {p: float(v) for p, v in bias_mm.items() if v is not None and np.isfinite(v)}
        self._dist = dict(distance_mm)
        self.update()

    def paintEvent(self, event) -> None:  # noqa: N802
        p = QPainter(self)
        poses = sorted(self.bias)
        if not poses:
            self._message(p, "No depth bias (the rig has no depth camera or no depth maps)")
            return
        vals = np.array([self.bias[q] for q in poses], float)
        spec = np.array([11.0 + 0.001 * self._dist.get(q, float("nan")) for q in poses])
        spec = np.where(np.isfinite(spec), spec, 11.0)
        lim = 1.25 * max(float(np.max(np.abs(vals))), float(np.max(spec)))
        panel = _Panel(QRectF(60, 24, self.width() - 72, self.height() - 62), len(poses), -lim, lim)
        _draw_axes(p, panel, "ToF bias per pose: measured depth on the board minus the calibrated board plane",
                   "bias (mm)", [q.replace("pose_", "") for q in poses], self._small())
        p.setPen(QPen(QColor("black"), 0.8))
        p.drawLine(QPointF(panel.rect.left(), panel.y(0)), QPointF(panel.rect.right(), panel.y(0)))
        for i, v in enumerate(vals):
            p.setBrush(QColor(WEAK if abs(v) > spec[i] else NORMAL))
            p.setPen(QPen(QColor("black"), 0.6))
            y0, y1 = panel.y(0), panel.y(v)
            p.drawRect(QRectF(panel.x(i) - panel.bar_w / 2, min(y0, y1), panel.bar_w, abs(y1 - y0)))
        p.setPen(QPen(QColor("#c0392b"), 1.2, Qt.PenStyle.DashLine))
        for i, s in enumerate(spec):
            xl, xr = panel.x(i) - panel.rect.width() / panel.n / 2, panel.x(i) + panel.rect.width() / panel.n / 2
            for sign in (1, -1):
                p.drawLine(QPointF(xl, panel.y(sign * s)), QPointF(xr, panel.y(sign * s)))
        p.setPen(QColor("#c0392b"))
        p.setFont(self._small())
        p.drawText(QRectF(panel.rect.left(), panel.rect.top() + 2, panel.rect.width() - 6, 16),
                   Qt.AlignmentFlag.AlignRight, "dashed: Azure Kinect spec ±(11 mm + 0.1 % of distance)")
        p.end()


def _sigma_colour(ratio: float) -> QColor:
    """Green (well below the camera's limit) -> yellow (at half) -> red (at the limit or above)."""
    if not math.isfinite(ratio):
        return QColor("#dddddd")
    t = min(max(ratio, 0.0), 1.0)
    hue = 120 - 120 * t
    return QColor.fromHsvF(hue / 360.0, 0.55, 1.0)


class UncertaintyMap(_Chart):
    """Projection uncertainty heat map per camera (mrcal-style): each grid cell coloured by its
    standard deviation (px) relative to the camera's limit, cells where no board corner was seen
    hatched, the three least certain cells outlined, the value written where the cell is big
    enough. One panel per camera, laid out in as many columns as make them largest."""

    def __init__(self, parent=None) -> None:
        super().__init__(parent, min_height=180)
        self._maps: list[dict] = []

    def set_data(self, maps: list[dict]) -> None:
        """``maps``: [{"camera", "sigma" (H, W) px, "corners" (H, W), "limit" px, "title"}]."""
        self._maps = list(maps)
        self.update()

    CAPTION = "σ in px, coloured relative to each camera's limit (its colour bar); hatched: no board corner seen there"

    @staticmethod
    def _wrapped_height(fm, text: str, width: float) -> int:
        """Height (px) of ``text`` word-wrapped to ``width`` px (its own line breaks kept)."""
        flags = int(Qt.TextFlag.TextWordWrap)
        return fm.boundingRect(QRect(0, 0, max(int(width), 1), 100000), flags, text).height()

    def paintEvent(self, event) -> None:  # noqa: N802
        p = QPainter(self)
        p.setRenderHint(QPainter.RenderHint.Antialiasing, False)
        if not self._maps:
            self._message(p, "No uncertainty yet: it is computed with the calibration.")
            return
        small = self._small()
        p.setFont(small)
        n = len(self._maps)
        W, H = self.width(), self.height()
        fm = p.fontMetrics()
        wrap = Qt.AlignmentFlag.AlignLeft | Qt.AlignmentFlag.AlignTop | Qt.TextFlag.TextWordWrap
        # titles and the one caption wrap instead of being cut: a panel ~220 px wide (four cameras
        # at 1280 x 720) showed "…least certai…" and "hatched…"
        cap_h = self._wrapped_height(fm, self.CAPTION, W - 8) + 4
        H_maps = max(H - cap_h, 1)
        aspect0 = float(np.median([m.get("aspect", 4 / 3) for m in self._maps]))

        def title_h(c: int) -> int:  # the tallest wrapped title with ``c`` columns
            return max(self._wrapped_height(fm, str(m["title"]), W / c - 8) for m in self._maps) + 6

        def size(c: int) -> float:  # panel width with ``c`` columns
            r = math.ceil(n / c)
            return min(W / c - 16, (H_maps / r - title_h(c) - 10) * aspect0)

        cols = max(range(1, n + 1), key=size)
        rows = math.ceil(n / cols)
        cw, ch = W / cols, H_maps / rows
        th = title_h(cols)
        for k, m in enumerate(self._maps):
            x0, y0 = (k % cols) * cw, (k // cols) * ch
            sig = np.asarray(m["sigma"], float)
            cnt = np.asarray(m["corners"])
            gh, gw = sig.shape
            aspect = m.get("aspect", gw / gh)
            lim = float(m["limit"])
            # this camera's colour bar (the colours are relative to its own limit): bar + tick labels
            bar_w = 10 + 6 + fm.horizontalAdvance(f"≥{lim:.2f}") + 4
            avail_w, avail_h = cw - 16 - bar_w, ch - th - 10
            pw = max(min(avail_w, avail_h * aspect), 1.0)
            ph = pw / aspect
            left, top = x0 + (cw - pw - bar_w) / 2, y0 + th + 4
            p.setPen(QColor("#222222"))
            p.drawText(QRectF(x0 + 4, y0 + 2, cw - 8, th), wrap, str(m["title"]))
            # outlined: where more views are asked for (only when a limit is exceeded)
            worst = set(np.argsort(-sig.ravel())[:3].tolist()) if m.get("needs_views", True) else set()
            sx, sy = pw / gw, ph / gh
            for i in range(gh):
                for j in range(gw):
                    r = QRectF(left + j * sx, top + i * sy, sx + 0.5, sy + 0.5)
                    p.fillRect(r, _sigma_colour(sig[i, j] / lim if lim > 0 else float("nan")))
                    if cnt[i, j] == 0:
                        p.fillRect(r, QBrush(QColor(0, 0, 0, 60), Qt.BrushStyle.BDiagPattern))
                    if i * gw + j in worst:
                        p.setPen(QPen(QColor("#c0392b"), 2))
                        p.drawRect(r.adjusted(1, 1, -1, -1))
                    if sx > fm.horizontalAdvance("00.0") + 4 and sy > fm.height():
                        p.setPen(QColor("#333333"))
                        v = sig[i, j]
                        p.drawText(r, Qt.AlignmentFlag.AlignCenter, f"{v:.1f}" if v < 100 else f"{v:.0f}")
            p.setPen(QPen(QColor("#333333"), 1))
            p.setBrush(Qt.BrushStyle.NoBrush)
            p.drawRect(QRectF(left, top, pw, ph))
            self._colour_bar(p, QRectF(left + pw + 8, top, 10, ph), lim)
        p.setPen(QColor("#333333"))
        p.drawText(QRectF(4, H - cap_h, W - 8, cap_h), wrap, self.CAPTION)

    @staticmethod
    def _colour_bar(p: QPainter, r: QRectF, lim: float) -> None:
        """A vertical colour bar in ``r``: 0 px at the bottom, the camera's limit ``lim`` (px) and
        above at the top, with its ticks labelled in px."""
        steps = max(2, int(r.height()))
        for k in range(steps):
            t = k / (steps - 1)
            p.fillRect(QRectF(r.left(), r.bottom() - (k + 1) * r.height() / steps, r.width(),
                              r.height() / steps + 0.5), _sigma_colour(t))
        p.setPen(QPen(QColor("#333333"), 1))
        p.drawRect(r)
        fm = p.fontMetrics()
        if not (lim > 0 and math.isfinite(lim)):
            return
        for frac, text in ((0.0, "0"), (0.5, f"{lim / 2:.2f}"), (1.0, f"≥{lim:.2f}")):
            y = r.bottom() - frac * r.height()
            p.drawLine(QPointF(r.right(), y), QPointF(r.right() + 3, y))
            ty = min(max(y - fm.height() / 2, r.top() - fm.height() / 2), r.bottom() - fm.height() / 2)
            p.drawText(QRectF(r.right() + 5, ty, fm.horizontalAdvance(text) + 2, fm.height()),
                       Qt.AlignmentFlag.AlignLeft | Qt.AlignmentFlag.AlignVCenter, text)
