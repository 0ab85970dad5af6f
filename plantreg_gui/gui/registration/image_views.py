"""Image views: a fast QGraphicsView for uint8 renderings, linked pan/zoom/cursor, a spectrum plot.

An :class:`ImageView` shows an (H, W, 3) uint8 array as a QImage pixmap (plus an optional
RGBA overlay and a crosshair). Views in one :class:`ViewLink` share zoom, scroll position and
cursor, as 3D Slicer's linked compare views do. Scene coordinates are image pixels with pixel
centres at integer + 0.5 (Qt's pixmap corner convention): pixel (row, col) = floor(y), floor(x).

Length: the raw and side-by-side views share the image canvas, its overlays, region drawing and
read-out; a module per view would import the canvas and little else.
"""

from __future__ import annotations

import numpy as np
from PySide6.QtCore import QEvent, QPointF, QRectF, Qt, QTimer, Signal
from PySide6.QtGui import QColor, QImage, QPainter, QPen, QPixmap, QPolygonF, QTransform
from PySide6.QtWidgets import (
    QFrame, QGraphicsItem, QGraphicsLineItem, QGraphicsPolygonItem, QGraphicsScene, QGraphicsView, QGridLayout,
    QHBoxLayout, QLabel, QSizePolicy, QVBoxLayout, QWidget,
)


def qimage_from_rgb8(rgb: np.ndarray) -> QImage:
    """(H, W, 3) uint8 -> QImage (RGB888), a deep copy so the array can go away."""
    a = np.ascontiguousarray(rgb, dtype=np.uint8)
    h, w = a.shape[:2]
    if a.ndim == 3 and a.shape[2] == 4:
        return QImage(a.data, w, h, 4 * w, QImage.Format.Format_RGBA8888).copy()
    return QImage(a.data, w, h, 3 * w, QImage.Format.Format_RGB888).copy()


def rgb8_from_qimage(img: QImage) -> np.ndarray:
    """QImage -> (H, W, 3) uint8 (for tests and exports)."""
    img = img.convertToFormat(QImage.Format.Format_RGB888)
    h, w, bpl = img.height(), img.width(), img.bytesPerLine()
    buf = np.frombuffer(img.constBits(), dtype=np.uint8, count=h * bpl).reshape(h, bpl)
    return buf[:, : 3 * w].reshape(h, w, 3).copy()


def region_outline(kind: str, shape) -> list[tuple[float, float]]:
    """The outline (x, y) corners of a region: ``("rect", (x0, y0, x1, y1))`` or
    ``("polygon", [(x, y), ...])`` (the session's region format)."""
    if kind == "rect":
        x0, y0, x1, y1 = shape
        return [(x0, y0), (x1, y0), (x1, y1), (x0, y1)]
    return [tuple(p) for p in shape]

class ImageItem(QGraphicsItem):
    """Draws a QImage as it is. (A QGraphicsPixmapItem would convert it to the screen's pixel
    format, e.g. 16-bit on some X servers, and lose the exact colours.)"""

    def __init__(self) -> None:
        super().__init__()
        self.image = QImage()

    def set_image(self, img: QImage) -> None:
        self.prepareGeometryChange()
        self.image = img
        self.update()

    def boundingRect(self) -> QRectF:  # noqa: N802
        return QRectF(0, 0, self.image.width(), self.image.height())

    def paint(self, painter: QPainter, option, widget=None) -> None:
        if not self.image.isNull():
            painter.drawImage(QPointF(0, 0), self.image)


class ImageView(QGraphicsView):
    """Shows one rendering; wheel zooms about the mouse, drag pans, double-click fits.

    Signals: ``hovered(row, col)`` image pixel under the mouse (-1, -1 when outside);
    ``region_drawn(kind, shape)`` when the user finished drawing a region in draw mode
    (:meth:`set_draw_mode`): ``("rect", (x0, y0, x1, y1))`` or ``("polygon", [(x, y), ...])`` in
    image pixel coordinates.
    """

    hovered = Signal(int, int)
    zoomed = Signal(object)  # QTransform
    region_drawn = Signal(str, object)

    def __init__(self, title: str = "", parent: QWidget | None = None):
        super().__init__(parent)
        self.title = title
        self.setScene(QGraphicsScene(self))
        self.setBackgroundBrush(QColor(40, 40, 40))
        self.setDragMode(QGraphicsView.DragMode.ScrollHandDrag)
        self.setTransformationAnchor(QGraphicsView.ViewportAnchor.AnchorUnderMouse)
        self.setRenderHint(QPainter.RenderHint.SmoothPixmapTransform, False)
        self.setMouseTracking(True)
        self.setFrameShape(QFrame.Shape.NoFrame)
        # no scroll bars (drag pans, the wheel zooms): a bar that appears when a fit zooms in
        # shrinks the viewport, whose resize refits and hides the bar again -- an endless loop
        # on the GUI thread, and a fit that ends with a bar shown cuts the image off
        self.setHorizontalScrollBarPolicy(Qt.ScrollBarPolicy.ScrollBarAlwaysOff)
        self.setVerticalScrollBarPolicy(Qt.ScrollBarPolicy.ScrollBarAlwaysOff)
        self.setMinimumSize(120, 100)
        self.setSizePolicy(QSizePolicy.Policy.Expanding, QSizePolicy.Policy.Expanding)
        self._pix = ImageItem()
        self._over = ImageItem()
        self._over.setZValue(1)
        self.scene().addItem(self._pix)
        self.scene().addItem(self._over)
        pen = QPen(QColor(255, 60, 60, 220))
        pen.setCosmetic(True)
        pen.setWidth(1)
        self._hline = QGraphicsLineItem()
        self._vline = QGraphicsLineItem()
        for ln in (self._hline, self._vline):
            ln.setPen(pen)
            ln.setZValue(2)
            ln.setVisible(False)
            self.scene().addItem(ln)
        rpen = QPen(QColor(255, 230, 0))
        rpen.setCosmetic(True)
        rpen.setWidth(2)
        self._region = QGraphicsPolygonItem()
        self._region.setPen(rpen)
        self._region.setZValue(3)
        self._region.setVisible(False)
        self.scene().addItem(self._region)
        self.draw_mode: str | None = None           # None, "rect" or "polygon"
        self._drawing: list[QPointF] = []           # corners while drawing
        self._outline: list[tuple[float, float]] = []  # the region shown when not drawing
        self.array: np.ndarray | None = None       # the (H, W, 3) uint8 shown
        self.overlay: np.ndarray | None = None     # the (H, W, 4) uint8 overlay shown
        self._auto_fit = True
        self.home_rect: QRectF | None = None  # what "fit" shows (e.g. the object's bounding box)

    # ---------------------------------------------------------------- content
    def set_rgb8(self, rgb: np.ndarray) -> None:
        first = self.array is None or self.array.shape[:2] != rgb.shape[:2]
        self.array = rgb
        self._pix.set_image(qimage_from_rgb8(rgb))
        h, w = rgb.shape[:2]
        self.scene().setSceneRect(QRectF(0, 0, w, h))
        self._hline.setLine(0, 0, w, 0)
        self._vline.setLine(0, 0, 0, h)
        if first:
            self._auto_fit = True
            self.fit()

    def set_overlay(self, rgba: np.ndarray | None) -> None:
        self.overlay = rgba
        self._over.set_image(QImage() if rgba is None else qimage_from_rgb8(rgba))

    def displayed(self) -> np.ndarray | None:
        """What the image item holds, read back from Qt, (H, W, 3) uint8."""
        img = self._pix.image
        return None if img.isNull() else rgb8_from_qimage(img)

    def clear(self) -> None:
        self.array = None
        self._pix.set_image(QImage())
        self.set_overlay(None)

    # ---------------------------------------------------------------- cursor, zoom
    def set_cursor_pixel(self, row: int, col: int) -> None:
        """Draw the crosshair through the centre of pixel (row, col); hide it for (-1, -1)."""
        show = row >= 0 and col >= 0 and self.array is not None
        self._hline.setVisible(show)
        self._vline.setVisible(show)
        if show:
            self._hline.setPos(0, row + 0.5)
            self._vline.setPos(col + 0.5, 0)

    def set_home(self, rect: QRectF | None) -> None:
        """The region that fitting (start, double-click) shows; None = the whole image."""
        self.home_rect = rect
        self._auto_fit = True
        self.fit()

    def fit(self) -> None:
        if self.array is not None:
            r = self.home_rect if self.home_rect is not None else self.scene().sceneRect()
            self.fitInView(r, Qt.AspectRatioMode.KeepAspectRatio)

    def resizeEvent(self, e) -> None:  # noqa: N802
        super().resizeEvent(e)
        if self._auto_fit:
            self.fit()

    # ---------------------------------------------------------------- region drawing
    def set_draw_mode(self, mode: str | None) -> None:
        """``"rect"`` (drag), ``"polygon"`` (click the corners, double-click to close) or None (pan)."""
        self.cancel_drawing()  # a half-drawn region does not outlive its tool
        self.draw_mode = mode
        self.setDragMode(QGraphicsView.DragMode.NoDrag if mode else QGraphicsView.DragMode.ScrollHandDrag)
        self.viewport().setCursor(Qt.CursorShape.CrossCursor if mode else Qt.CursorShape.OpenHandCursor)

    def set_region_outline(self, points: list[tuple[float, float]] | None) -> None:
        """Draw a region's outline (image pixel coordinates); None hides it."""
        self._outline = list(points or [])  # what Escape goes back to while drawing
        self._draw_outline(points)

    def _draw_outline(self, points: list[tuple[float, float]] | None) -> None:
        self._region.setVisible(bool(points))
        self._region.setPolygon(QPolygonF([QPointF(x, y) for x, y in (points or [])]))

    def cancel_drawing(self) -> bool:
        """Drop the region being drawn (Escape); the region drawn before stays. True if one was."""
        if not self._drawing:
            return False
        self._drawing = []
        self._draw_outline(self._outline)
        return True

    def keyPressEvent(self, e) -> None:  # noqa: N802
        if e.key() == Qt.Key.Key_Escape and self.cancel_drawing():
            e.accept()
            return
        super().keyPressEvent(e)

    def _scene_pos(self, e) -> QPointF:
        return self.mapToScene(e.position().toPoint())

    def mousePressEvent(self, e) -> None:  # noqa: N802
        if self.draw_mode and e.button() == Qt.MouseButton.LeftButton and self.array is not None:
            self.setFocus(Qt.FocusReason.MouseFocusReason)  # Escape reaches this view while drawing
            p = self._scene_pos(e)
            if self.draw_mode == "rect":
                self._drawing = [p, p]
            else:
                if self._drawing:  # the corner that followed the mouse stays here
                    self._drawing[-1] = p
                self._drawing = (self._drawing or [p]) + [p]  # the last corner follows the mouse
            self._show_drawing()
            return
        super().mousePressEvent(e)

    def mouseReleaseEvent(self, e) -> None:  # noqa: N802
        if self.draw_mode == "rect" and self._drawing and e.button() == Qt.MouseButton.LeftButton:
            a, b = self._drawing[0], self._scene_pos(e)
            self._drawing = []
            if abs(b.x() - a.x()) >= 1 and abs(b.y() - a.y()) >= 1:  # a click is not a region
                self.region_drawn.emit("rect", (a.x(), a.y(), b.x(), b.y()))
            return
        super().mouseReleaseEvent(e)

    def _show_drawing(self) -> None:
        d = self._drawing
        if self.draw_mode == "rect" and len(d) == 2:
            a, b = d
            pts = region_outline("rect", (a.x(), a.y(), b.x(), b.y()))
        else:
            pts = [(p.x(), p.y()) for p in d]
        self._draw_outline(pts)

    def mouseDoubleClickEvent(self, e) -> None:  # noqa: N802
        if self.draw_mode == "polygon" and e.button() == Qt.MouseButton.LeftButton:
            corners = [(p.x(), p.y()) for p in self._drawing[:-1]]  # the last one follows the mouse
            # a double click also sent a press: drop the duplicate corners it added
            dedup = [c for i, c in enumerate(corners) if i == 0 or np.hypot(c[0] - corners[i - 1][0],
                                                                             c[1] - corners[i - 1][1]) > 0.5]
            self._drawing = []
            if len(dedup) >= 3:
                self.region_drawn.emit("polygon", dedup)
            return
        if self.draw_mode:
            return
        self._auto_fit = True
        self.fit()
        self.zoomed.emit(self.transform())

    def wheelEvent(self, e) -> None:  # noqa: N802
        steps = e.angleDelta().y() / 120.0
        if steps == 0:
            return
        self.zoom_by(1.25 ** steps)

    def zoom_by(self, factor: float) -> None:
        self._auto_fit = False
        self.scale(factor, factor)
        self.zoomed.emit(self.transform())

    def apply_transform(self, t: QTransform) -> None:
        self._auto_fit = False
        if t != self.transform():
            self.setTransform(t)

    def mouseMoveEvent(self, e) -> None:  # noqa: N802
        super().mouseMoveEvent(e)
        p = self.mapToScene(e.position().toPoint())
        if self.draw_mode and self._drawing:
            self._drawing[-1] = p
            self._show_drawing()
        self.hover_scene(p)

    def hover_scene(self, p: QPointF) -> None:
        if self.array is None:
            return
        h, w = self.array.shape[:2]
        col, row = int(np.floor(p.x())), int(np.floor(p.y()))
        if 0 <= row < h and 0 <= col < w:
            self.hovered.emit(row, col)
        else:
            self.hovered.emit(-1, -1)

    def leaveEvent(self, e) -> None:  # noqa: N802
        super().leaveEvent(e)
        self.hovered.emit(-1, -1)


class ViewLink:
    """Links views' zoom, scroll and cursor (all views show images of one pixel grid)."""

    def __init__(self) -> None:
        self.views: list[ImageView] = []

    def add(self, v: ImageView) -> None:
        self.views.append(v)
        v.zoomed.connect(lambda t, src=v: self._zoom(src, t))
        # setValue with an unchanged value emits nothing, so this cannot loop
        v.horizontalScrollBar().valueChanged.connect(lambda val, src=v: self._scroll(src, val, True))
        v.verticalScrollBar().valueChanged.connect(lambda val, src=v: self._scroll(src, val, False))

    def clear(self) -> None:
        self.views.clear()

    def _zoom(self, src: ImageView, t: QTransform) -> None:
        c = src.mapToScene(src.viewport().rect().center())
        for v in self.views:
            if v is not src:
                v.apply_transform(t)
                v.centerOn(c)

    def _scroll(self, src: ImageView, val: int, horizontal: bool) -> None:
        if src._auto_fit:
            return
        for v in self.views:
            if v is not src:
                (v.horizontalScrollBar() if horizontal else v.verticalScrollBar()).setValue(val)

    def set_cursor(self, row: int, col: int) -> None:
        for v in self.views:
            v.set_cursor_pixel(row, col)


class TitledView(QWidget):
    """An ImageView with a caption above it."""

    def __init__(self, title: str, parent: QWidget | None = None):
        super().__init__(parent)
        lay = QVBoxLayout(self)
        lay.setContentsMargins(2, 2, 2, 2)
        lay.setSpacing(1)
        self.label = QLabel(title)
        self.label.setStyleSheet("font-weight: bold;")
        self.view = ImageView(title)
        # a long title wraps onto a second line, never widens the grid ("hyperspectral (reflectance,
        # 100 bands, 640x576)" was cut in a third of a 1280 px window)
        self.label.setWordWrap(True)
        self.label.setMinimumWidth(40)
        self.bar = ColourBar()
        lay.addWidget(self.label)
        lay.addWidget(self.bar)  # its own row: beside the title it squeezed the title and the side panel
        lay.addWidget(self.view, 1)


class ColourBar(QWidget):
    """A colour map's gradient with its limits in the image's unit, e.g. ``18.2 [▆▆▆] 26.1 °C``
    (what a colour means is part of the picture); hidden for colour and multi-band images."""

    def __init__(self, parent: QWidget | None = None):
        super().__init__(parent)
        lay = QHBoxLayout(self)
        lay.setContentsMargins(0, 0, 0, 0)
        lay.setSpacing(3)
        self.lo, self.ramp, self.hi = QLabel(""), QLabel(), QLabel("")
        for w in (self.lo, self.ramp, self.hi):
            w.setStyleSheet("font-size: 11px;")
            lay.addWidget(w)
        lay.addStretch(1)
        # the ramp shrinks with a narrow view (three bars side by side made the window too wide)
        self.ramp.setScaledContents(True)
        self.ramp.setMinimumWidth(40)
        self.ramp.setMaximumWidth(160)
        self.ramp.setSizePolicy(QSizePolicy.Policy.Preferred, QSizePolicy.Policy.Fixed)
        self.cmap: str | None = None
        self.limits: tuple[float, float] | None = None
        self.hide()

    def set_bar(self, cmap: str | None, limits: tuple[float, float] | None, unit: str = "") -> None:
        self.cmap, self.limits = cmap, limits
        if cmap is None or limits is None:
            self.hide()
            return
        from ...core.display import display

        lut = display.colormap_lut(cmap)
        ramp = np.ascontiguousarray(np.repeat(lut[None, :, :], 10, axis=0))
        img = QImage(ramp.data, 256, 10, 256 * 3, QImage.Format.Format_RGB888).scaled(160, 10)
        self.ramp.setPixmap(QPixmap.fromImage(img))
        fmt = (lambda v: f"{v:.1f}") if max(abs(limits[0]), abs(limits[1])) < 1000 else (lambda v: f"{v:.0f}")
        self.lo.setText(fmt(limits[0]))
        self.hi.setText(fmt(limits[1]) + (f" {unit}" if unit else ""))
        self.show()


class ViewGrid(QWidget):
    """A grid of titled image views, one per layer; optionally linked."""

    hovered = Signal(str, int, int)  # (layer name, row, col)

    def __init__(self, linked: bool, parent: QWidget | None = None):
        super().__init__(parent)
        self.linked = linked
        self.link = ViewLink()
        self.grid = QGridLayout(self)
        self.grid.setContentsMargins(0, 0, 0, 0)
        self.grid.setSpacing(4)
        self.views: dict[str, TitledView] = {}

    def set_layers(self, names: list[str], titles: dict[str, str]) -> None:
        if list(self.views) == names:
            for n in names:
                self.views[n].label.setText(titles.get(n, n))
            self._align_titles()
            return
        for tv in self.views.values():
            self.grid.removeWidget(tv)
            tv.deleteLater()
        self.views.clear()
        self.link.clear()
        n = len(names)
        cols = 1 if n <= 1 else 2 if n <= 4 else 3
        for i, name in enumerate(names):
            tv = TitledView(titles.get(name, name))
            self.views[name] = tv
            self.grid.addWidget(tv, i // cols, i % cols)
            tv.view.hovered.connect(lambda r, c, nm=name: self.hovered.emit(nm, r, c))
            if self.linked:
                self.link.add(tv.view)
            tv.label.installEventFilter(self)
        self._align_titles()

    def eventFilter(self, obj, event) -> bool:  # noqa: N802 (Qt name)
        if event.type() in (QEvent.Type.Resize, QEvent.Type.Show) and isinstance(obj, QLabel):  # a title's width
            self._align_titles()
        return False

    def _align_titles(self) -> None:
        """The titles of one grid row take the height of its tallest (wrapped) one, and a view
        without a colour bar keeps the bar's room when another view of its row has one (a colour
        image beside a depth map sat a bar's height higher), so that the row's images line up."""
        rows: dict[int, list[TitledView]] = {}
        for tv in self.views.values():
            row = self.grid.getItemPosition(self.grid.indexOf(tv))[0]
            any_bar = any(not t.bar.isHidden() for t in self.views.values()
                          if self.grid.getItemPosition(self.grid.indexOf(t))[0] == row)
            sp = tv.bar.sizePolicy()
            if sp.retainSizeWhenHidden() != any_bar:
                sp.setRetainSizeWhenHidden(any_bar)
                tv.bar.setSizePolicy(sp)
            if tv.label.isVisible():  # laid out: its width is the column's (shown, it resizes again)
                rows.setdefault(row, []).append(tv)
        for tvs in rows.values():
            h = max(tv.label.heightForWidth(tv.label.width()) for tv in tvs)
            for tv in tvs:
                tv.label.setMinimumHeight(h)

    def set_image(self, name: str, rgb: np.ndarray) -> None:
        self.views[name].view.set_rgb8(rgb)

    def set_cursor(self, row: int, col: int) -> None:
        if self.linked:
            self.link.set_cursor(row, col)

    def set_home(self, rect: QRectF | None) -> None:
        for tv in self.views.values():
            tv.view.set_home(rect)


class SpectrumPlot(QWidget):
    """The spectrum of the pixel under the cursor (matplotlib), redrawn at most every 60 ms."""

    def __init__(self, parent: QWidget | None = None):
        super().__init__(parent)
        from matplotlib.figure import Figure

        from ..resize_hold import canvas_class

        # fixed margins: a constrained layout is re-solved on every draw (a stall of the GUI thread)
        self.figure = Figure(figsize=(4, 1.6), dpi=90)
        self.figure.subplots_adjust(left=0.17, right=0.97, top=0.86, bottom=0.25)
        self.canvas = canvas_class()(self.figure)  # redraws at a new size in a turn of its own
        self.ax = self.figure.add_subplot(111)
        lay = QVBoxLayout(self)
        lay.setContentsMargins(0, 0, 0, 0)
        lay.addWidget(self.canvas)
        self.setMinimumHeight(150)
        self._line = None
        self._pending: tuple | None = None
        self.current: np.ndarray | None = None
        self._timer = QTimer(self)
        self._timer.setSingleShot(True)
        self._timer.setInterval(60)
        self._timer.timeout.connect(self._draw)
        self.set_spectrum(None, None, "move the cursor over the hyperspectral image")

    def set_spectrum(self, values: np.ndarray | None, wavelengths: np.ndarray | None, title: str,
                     unit: str = "") -> None:
        """``unit`` of the values (the camera's, e.g. reflectance): the value axis's label."""
        self.current = values
        self._pending = (values, wavelengths, title, unit)
        if not self._timer.isActive():
            self._timer.start()

    def _draw(self) -> None:
        """Update the one line in place (clearing and re-plotting the axes costs far more)."""
        if self._pending is None:
            return
        values, wl, title, unit = self._pending
        self._pending = None
        ax = self.ax
        if self._line is None:
            ax.tick_params(labelsize=7)
            (self._line,) = ax.plot([], [], color="#2a7f2a", lw=1.2)
            self._note = ax.text(0.5, 0.5, "", transform=ax.transAxes, ha="center", va="center", fontsize=8,
                                 color="#555")
        ax.set_title(title, fontsize=8)
        ok = values is not None and bool(np.any(np.isfinite(values)))
        self._line.set_visible(ok)
        # an unmapped pixel says so instead of showing empty axes with made-up 0-1 limits
        self.empty = not ok
        self._note.set_text("" if ok else ("no value at this pixel (not mapped)" if values is not None
                                            else "move the cursor over the image"))
        ax.xaxis.set_visible(ok)
        ax.yaxis.set_visible(ok)
        if ok:
            x = wl if wl is not None else np.arange(values.size)
            self._line.set_data(x, values)
            ax.set_xlabel("wavelength (nm)" if wl is not None else "band", fontsize=7)
            ax.set_ylabel(unit or "value", fontsize=7)
            ax.relim()
            ax.autoscale_view()
        self.canvas.draw_idle()


# ---------------------------------------------------------------------- the workspace's image grids
class RawImagesView(ViewGrid):
    """The recording's raw images, one unlinked view each (each in its own pixel grid)."""

    needs = "raw"

    def __init__(self, session, parent: QWidget | None = None):
        super().__init__(linked=False, parent=parent)
        self.session = session
        session.events.raw.connect(self._refresh)
        session.events.display.connect(self._display)
        self.hovered.connect(lambda name, r, c: session.hover(name, r, c))

    def _refresh(self) -> None:
        s = self.session
        self.set_layers([L.name for L in s.raw], {L.name: s.layer_title(L, raw=True) for L in s.raw})
        for L in s.raw:
            self.set_image(L.name, s.raw_renders[L.name])
            self.views[L.name].bar.set_bar(*s.colour_bar(L))
        self._align_titles()  # the bars shown now

    def _display(self, name: str) -> None:
        L = self.session.layer(name, registered=False)
        if name in self.views and L is not None:
            self.set_image(name, self.session.raw_renders[name])
            self.views[name].bar.set_bar(*self.session.colour_bar(L))


class SideBySideView(ViewGrid):
    """Every registered image in the target grid, zoom, pan and cursor linked."""

    needs = "result"

    def __init__(self, session, parent: QWidget | None = None):
        super().__init__(linked=True, parent=parent)
        self.session = session
        session.events.result.connect(self._refresh)
        session.events.display.connect(self._display)
        session.events.cursor.connect(self._cursor)
        self.hovered.connect(lambda _name, r, c: session.hover("target", r, c))
        session.events.region.connect(self._region)
        self.draw_mode: str | None = None

    def _refresh(self) -> None:
        s = self.session
        before = list(self.views)
        self.set_layers([L.name for L in s.layers], {L.name: s.layer_title(L) for L in s.layers})
        for L in s.layers:
            self.set_image(L.name, s.renders[L.name])
            self.views[L.name].bar.set_bar(*s.colour_bar(L))
        self._align_titles()  # the bars shown now
        if list(self.views) != before:  # new views: they draw regions too
            for tv in self.views.values():
                tv.view.region_drawn.connect(s.set_region)
                tv.view.set_draw_mode(self.draw_mode)
        self.set_home(home_rect(s.home))
        self._region()

    def set_draw_mode(self, mode: str | None) -> None:
        """Draw a region (``"rect"`` / ``"polygon"``) on any of the linked views, or pan (None)."""
        self.draw_mode = mode
        for tv in self.views.values():
            tv.view.set_draw_mode(mode)

    def _region(self) -> None:
        """Outline the session's region on every view."""
        reg = self.session.region
        pts = None if reg is None else region_outline(*reg)
        for tv in self.views.values():
            tv.view.set_region_outline(pts)

    def _display(self, name: str) -> None:
        L = self.session.layer(name)
        if name in self.views and L is not None:
            self.set_image(name, self.session.renders[name])
            self.views[name].bar.set_bar(*self.session.colour_bar(L))

    def _cursor(self) -> None:
        c = self.session.cursor
        if c is not None and c[0] == "target":
            self.set_cursor(c[1], c[2])


def home_rect(box: tuple[float, float, float, float] | None) -> QRectF | None:
    """The session's object box (x0, y0, x1, y1) as a scene rectangle."""
    if box is None:
        return None
    x0, y0, x1, y1 = box
    return QRectF(x0, y0, x1 - x0, y1 - y0)
