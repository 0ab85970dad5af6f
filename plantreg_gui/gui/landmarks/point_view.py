"""An image view that shows landmarks and lets the user click, select and drag them.

Image pixels ``uv`` have their centres at integer coordinates (plantreg's convention); the
scene (see registration/image_views.py) has them at integer + 0.5, hence the 0.5 shifts.
A click (press and release without moving) emits ``clicked(u, v)``; a press on a marker selects
it and dragging moves it with sub-pixel precision (``drag_started``, ``dragged``,
``drag_finished``); a drag elsewhere pans, the wheel zooms about the mouse.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from PySide6.QtCore import QPointF, QRectF, Qt, Signal
from PySide6.QtGui import QColor, QFont, QFontMetricsF, QPainter, QPen
from PySide6.QtWidgets import QGraphicsView

from ..registration.image_views import ImageView
from .labels import leader_end, place_labels

_PICK_PX = 9.0  # screen pixels: how close a press must be to a marker to grab it


@dataclass
class Marker:
    index: int
    uv: np.ndarray                  # (2,) where the user clicked
    label: str                      # e.g. "3  1.2 px"
    predicted: np.ndarray | None = None  # (2,) where the rig puts it (drawn as a residual line)
    colour: tuple[int, int, int] = (255, 220, 0)


class PointView(ImageView):
    clicked = Signal(float, float)          # u, v
    marker_pressed = Signal(int)            # index
    drag_started = Signal(int)
    dragged = Signal(int, float, float)     # index, u, v
    drag_finished = Signal(int, float, float)

    def __init__(self, title: str = "", parent=None):
        super().__init__(title, parent)
        self.markers: list[Marker] = []
        self.selected: int | None = None
        self.pending: np.ndarray | None = None
        self._press = None
        self._drag: int | None = None
        self._moved = False
        #: False while a click here completes a pair: then a click near a marker adds, not grabs
        self.grab_markers = True

    def set_markers(self, markers: list[Marker], selected: int | None, pending: np.ndarray | None = None) -> None:
        self.markers, self.selected, self.pending = markers, selected, pending
        self.viewport().update()

    # ---------------------------------------------------------------- mouse
    def _uv(self, pos) -> np.ndarray:
        p = self.mapToScene(pos)
        return np.array([p.x() - 0.5, p.y() - 0.5])

    def _marker_at(self, pos) -> int | None:
        best, best_d = None, _PICK_PX
        for m in self.markers:
            s = self.mapFromScene(QPointF(m.uv[0] + 0.5, m.uv[1] + 0.5))
            d = float(np.hypot(s.x() - pos.x(), s.y() - pos.y()))
            if d < best_d:
                best, best_d = m.index, d
        return best

    def mousePressEvent(self, e) -> None:  # noqa: N802
        if e.button() == Qt.MouseButton.LeftButton and self.array is not None:
            pos = e.position().toPoint()
            self._press, self._moved = pos, False
            hit = self._marker_at(pos) if self.grab_markers else None
            if hit is not None:
                self._drag = hit
                self.setDragMode(QGraphicsView.DragMode.NoDrag)
                self.marker_pressed.emit(hit)
                return
        super().mousePressEvent(e)

    def mouseMoveEvent(self, e) -> None:  # noqa: N802
        if self._press is not None:
            pos = e.position().toPoint()
            if (pos - self._press).manhattanLength() > 3:
                if self._drag is not None and not self._moved:
                    self.drag_started.emit(self._drag)
                self._moved = True
            if self._drag is not None and self._moved:
                u, v = self._uv(pos)
                self.dragged.emit(self._drag, float(u), float(v))
                self.hover_scene(self.mapToScene(pos))
                return
        super().mouseMoveEvent(e)

    def mouseReleaseEvent(self, e) -> None:  # noqa: N802
        if e.button() == Qt.MouseButton.LeftButton and self._press is not None:
            pos = e.position().toPoint()
            if self._drag is not None:
                if self._moved:
                    u, v = self._uv(pos)
                    self.drag_finished.emit(self._drag, float(u), float(v))
                self.setDragMode(QGraphicsView.DragMode.ScrollHandDrag)
            elif not self._moved:
                u, v = self._uv(pos)
                h, w = self.array.shape[:2]
                if -0.5 <= u < w - 0.5 and -0.5 <= v < h - 0.5:
                    self.clicked.emit(float(u), float(v))
            self._press, self._drag = None, None
        super().mouseReleaseEvent(e)

    # ---------------------------------------------------------------- drawing
    def drawForeground(self, painter: QPainter, rect: QRectF) -> None:  # noqa: N802
        super().drawForeground(painter, rect)
        if self.array is None:
            return
        painter.save()
        painter.resetTransform()  # draw in screen pixels: markers keep their size at any zoom
        painter.setRenderHint(QPainter.RenderHint.Antialiasing, True)
        f = QFont(painter.font())
        f.setPointSize(9)
        f.setBold(True)
        painter.setFont(f)

        def screen(uv) -> QPointF:
            return QPointF(self.mapFromScene(QPointF(uv[0] + 0.5, uv[1] + 0.5)))

        # labels placed inside the view and off each other (near points, e.g. two corners of one
        # leaf, wrote over each other; labels at the right edge were cut off)
        fm = QFontMetricsF(f)
        pts = [screen(m.uv) for m in self.markers]
        vp = self.viewport().rect()
        boxes = place_labels([(p.x(), p.y()) for p in pts],
                             [(fm.horizontalAdvance(m.label) + 2.0, fm.height() + 2.0) for m in self.markers],
                             (0.0, 0.0, float(vp.width()), float(vp.height())))
        for m, p in zip(self.markers, pts):
            sel = m.index == self.selected
            col = QColor(0, 255, 255) if sel else QColor(*m.colour)
            if m.predicted is not None:  # residual: from the click to where the rig puts the point
                q = screen(m.predicted)
                pen = QPen(QColor(255, 80, 80), 1.5)
                painter.setPen(pen)
                painter.drawLine(p, q)
                painter.drawEllipse(q, 2.0, 2.0)
            painter.setPen(QPen(QColor(0, 0, 0), 4.0))
            painter.drawEllipse(p, 5.0, 5.0)
            painter.setPen(QPen(col, 2.0))
            painter.drawEllipse(p, 5.0, 5.0)
            painter.drawPoint(p)
        for m, p, box in zip(self.markers, pts, boxes):  # labels over all markers
            col = QColor(0, 255, 255) if m.index == self.selected else QColor(*m.colour)
            end = leader_end((p.x(), p.y()), box)
            if end is not None:  # a label moved away from its point: a thin line says whose it is
                painter.setPen(QPen(col, 1.0))
                painter.drawLine(p, QPointF(*end))
            # the label with a dark halo so it reads on bright leaves and dark background alike
            tp = QPointF(box[0] + 1.0, box[1] + 1.0 + fm.ascent())
            painter.setPen(QPen(QColor(0, 0, 0)))
            for dx, dy in ((-1, 0), (1, 0), (0, -1), (0, 1)):
                painter.drawText(tp + QPointF(dx, dy), m.label)
            painter.setPen(QPen(col))
            painter.drawText(tp, m.label)
        if self.pending is not None:
            p = screen(self.pending)
            painter.setPen(QPen(QColor(255, 0, 255), 2.0))
            painter.drawLine(p + QPointF(-9, 0), p + QPointF(9, 0))
            painter.drawLine(p + QPointF(0, -9), p + QPointF(0, 9))
            painter.drawEllipse(p, 6.0, 6.0)
        painter.restore()
