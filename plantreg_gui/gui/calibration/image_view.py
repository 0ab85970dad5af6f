"""Zoomable image view with the detected corners drawn in their order.

The order matters more than the positions: a board detected rotated by 180 degrees in one
camera has perfect-looking corners and wrecks the extrinsics. So corner 0 gets a big ring and
the label "0", the first row is drawn thick with an arrow towards corner 1, and the polyline
through all corners runs through a colour gradient (red at corner 0 -> blue at the last).
"""

from __future__ import annotations

import math

import numpy as np
from PySide6.QtCore import QPointF, QRectF, Qt, Signal
from PySide6.QtGui import QBrush, QColor, QFont, QPainter, QPainterPath, QPen, QPolygonF
from PySide6.QtWidgets import (QGraphicsEllipseItem, QGraphicsPathItem, QGraphicsPixmapItem,
                               QGraphicsScene, QGraphicsSimpleTextItem, QGraphicsView)

from .widgets import qpixmap


def order_colour(t: float) -> QColor:
    """Colour of position ``t`` in [0, 1] along the corner order: red -> yellow -> green -> blue."""
    return QColor.fromHsvF(max(0.0, min(1.0, t)) * 0.66, 1.0, 1.0)


class ImageView(QGraphicsView):
    """QGraphicsView of one image; wheel zooms around the cursor, drag pans, double-click fits."""

    zoomed = Signal(float)

    def __init__(self, parent=None) -> None:
        super().__init__(parent)
        self.setScene(QGraphicsScene(self))
        self.setRenderHints(QPainter.RenderHint.Antialiasing | QPainter.RenderHint.SmoothPixmapTransform)
        self.setDragMode(QGraphicsView.DragMode.ScrollHandDrag)
        self.setTransformationAnchor(QGraphicsView.ViewportAnchor.AnchorUnderMouse)
        self.setBackgroundBrush(QColor("#303030"))
        self._pixmap: QGraphicsPixmapItem | None = None
        self._overlay: list = []
        self._message: QGraphicsSimpleTextItem | None = None
        self.corner_count = 0
        self._fitted = True
        self._resid_items: list = []
        self.residual_segments = np.zeros((0, 2, 2))  # (N, 2 ends, xy) of the drawn residual vectors

    # ------------------------------------------------------------------ content
    def clear(self, message: str = "") -> None:
        self.scene().clear()
        self._pixmap = None
        self._overlay = []
        self._resid_items = []
        self.corner_count = 0
        if message:
            t = self.scene().addSimpleText(message)
            t.setBrush(QColor("white"))
            f = QFont()
            f.setPointSize(12)
            t.setFont(f)
            self.scene().setSceneRect(t.boundingRect().adjusted(-20, -20, 20, 20))

    def set_image(self, img: np.ndarray) -> None:
        """``img`` uint8 (H, W) or (H, W, 3)."""
        self.scene().clear()
        self._overlay = []
        self._resid_items = []
        self.corner_count = 0
        self.image = img  # what is shown (the corner review's tests look at it)
        self._pixmap = self.scene().addPixmap(qpixmap(img))
        self._pixmap.setTransformationMode(Qt.TransformationMode.SmoothTransformation)
        h, w = img.shape[:2]
        # pixel centres at integer coordinates: pixel (0, 0) covers [-0.5, 0.5]
        self._pixmap.setOffset(-0.5, -0.5)
        self.scene().setSceneRect(QRectF(-0.5, -0.5, w, h))
        self.fit()

    def set_corners(self, corners: np.ndarray | None, columns: int, ids: np.ndarray | None = None) -> None:
        """Draw corners (N, 2) in order; ``columns`` corners per board row (chessboard order)."""
        for it in self._overlay:
            self.scene().removeItem(it)
        self._overlay = []
        self.corner_count = 0
        if corners is None or len(corners) == 0:
            return
        pts = np.asarray(corners, dtype=np.float64).reshape(-1, 2)
        n = len(pts)
        self.corner_count = n
        steps = np.linalg.norm(np.diff(pts, axis=0), axis=1) if n > 1 else np.array([10.0])
        spacing = float(np.median(steps)) if len(steps) else 10.0
        r = max(1.2, 0.11 * spacing)
        w = max(1.0, 0.08 * spacing)
        # polyline through the corners in order, colour graded
        for i in range(n - 1):
            new_row = columns > 0 and ids is None and (i + 1) % columns == 0
            pen = QPen(order_colour(i / max(n - 1, 1)), w * (0.5 if new_row else 1.0))
            if new_row:
                pen.setStyle(Qt.PenStyle.DotLine)
            path = QPainterPath(QPointF(*pts[i]))
            path.lineTo(QPointF(*pts[i + 1]))
            self._add(QGraphicsPathItem(path), pen=pen)
        for i, (x, y) in enumerate(pts):
            c = order_colour(i / max(n - 1, 1))
            e = QGraphicsEllipseItem(x - r, y - r, 2 * r, 2 * r)
            self._add(e, pen=QPen(QColor("black"), w * 0.5), brush=QBrush(c))
        # corner 0: a big ring and the label; an arrow along the first row
        x0, y0 = pts[0]
        R = 2.6 * r + spacing * 0.25
        ring = QGraphicsEllipseItem(x0 - R, y0 - R, 2 * R, 2 * R)
        self._add(ring, pen=QPen(QColor("#ff2020"), 2.2 * w))
        if n > 1:
            self._arrow(pts[0], pts[min(columns - 1, n - 1)] if columns > 1 else pts[1], spacing, w)
        label = QGraphicsSimpleTextItem("0")
        f = QFont()
        f.setBold(True)
        f.setPixelSize(max(8, int(1.4 * R)))
        label.setFont(f)
        label.setBrush(QColor("#ff2020"))
        label.setPen(QPen(QColor("black"), 0.06 * R))
        br = label.boundingRect()
        label.setPos(x0 - R - br.width() - 0.2 * R, y0 - R - br.height() * 0.8)
        self._add(label)

    def set_residuals(self, corners: np.ndarray | None, residuals: np.ndarray | None, scale: float) -> None:
        """Draw each corner's residual vector (N, 2) px from its corner (N, 2), ``scale`` times
        longer than it is (magenta, with a head); None clears them."""
        for it in getattr(self, "_resid_items", []):
            self.scene().removeItem(it)
        self._resid_items: list = []
        self.residual_segments = np.zeros((0, 2, 2))
        if corners is None or residuals is None or len(corners) == 0:
            return
        a = np.asarray(corners, np.float64).reshape(-1, 2)
        b = a + scale * np.asarray(residuals, np.float64).reshape(-1, 2)
        self.residual_segments = np.stack([a, b], axis=1)
        steps = np.linalg.norm(np.diff(a, axis=0), axis=1)
        w = max(1.0, 0.05 * float(np.median(steps))) if len(steps) else 1.0
        pen = QPen(QColor("#ff00ff"), w)
        pen.setCapStyle(Qt.PenCapStyle.RoundCap)
        for (x0, y0), (x1, y1) in zip(a, b):
            path = QPainterPath(QPointF(x0, y0))
            path.lineTo(QPointF(x1, y1))
            d = np.array([x1 - x0, y1 - y0])
            L = float(np.hypot(*d))
            if L > 4 * w:  # a head where it can be seen
                u, n = d / L, np.array([-d[1], d[0]]) / L
                for side in (1, -1):
                    h = np.array([x1, y1]) - u * 3 * w + side * n * 1.8 * w
                    path.moveTo(QPointF(x1, y1))
                    path.lineTo(QPointF(*h))
            it = QGraphicsPathItem(path)
            it.setPen(pen)
            it.setZValue(5)
            self.scene().addItem(it)
            self._resid_items.append(it)

    def focus_corners(self, corners: np.ndarray, margin: float = 0.45) -> None:
        """Zoom onto the board: its corners' bounding box grown by ``margin`` of its size each side."""
        pts = np.asarray(corners, dtype=np.float64).reshape(-1, 2)
        if len(pts) < 2 or self._pixmap is None:
            return
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        size = np.maximum(hi - lo, 10.0)
        lo, hi = lo - margin * size, hi + margin * size
        rect = QRectF(lo[0], lo[1], hi[0] - lo[0], hi[1] - lo[1]).intersected(self.scene().sceneRect())
        self.fitInView(rect, Qt.AspectRatioMode.KeepAspectRatio)
        self._fitted = False

    def _arrow(self, a: np.ndarray, b: np.ndarray, spacing: float, w: float) -> None:
        d = np.asarray(b, float) - np.asarray(a, float)
        L = float(np.hypot(*d))
        if L < 1e-6:
            return
        u = d / L
        tip = np.asarray(a) + u * min(L, 2.2 * spacing)
        path = QPainterPath(QPointF(*a))
        path.lineTo(QPointF(*tip))
        self._add(QGraphicsPathItem(path), pen=QPen(QColor("#ff2020"), 2.5 * w))
        head = 0.5 * spacing
        n = np.array([-u[1], u[0]])
        poly = QPolygonF([QPointF(*(tip + u * head * 0.6)), QPointF(*(tip - u * head * 0.4 + n * head * 0.45)),
                          QPointF(*(tip - u * head * 0.4 - n * head * 0.45))])
        it = self.scene().addPolygon(poly, QPen(QColor("black"), 0.5 * w), QBrush(QColor("#ff2020")))
        self._overlay.append(it)

    def _add(self, it, pen: QPen | None = None, brush: QBrush | None = None):
        if pen is not None:
            it.setPen(pen)
        if brush is not None:
            it.setBrush(brush)
        self.scene().addItem(it)
        self._overlay.append(it)
        return it

    # ------------------------------------------------------------------ zoom
    def fit(self) -> None:
        self._fitted = True
        if self._pixmap is not None:
            self.fitInView(self.scene().sceneRect(), Qt.AspectRatioMode.KeepAspectRatio)

    def zoom_factor(self) -> float:
        return float(self.transform().m11())

    def wheelEvent(self, event) -> None:  # noqa: N802 (Qt name)
        s = math.pow(1.0015, event.angleDelta().y())
        z = self.zoom_factor() * s
        if 0.02 < z < 60:
            self.scale(s, s)
            self._fitted = False
            self.zoomed.emit(self.zoom_factor())

    def mouseDoubleClickEvent(self, event) -> None:  # noqa: N802
        self.fit()

    def resizeEvent(self, event) -> None:  # noqa: N802
        super().resizeEvent(event)
        if self._fitted:
            self.fit()
