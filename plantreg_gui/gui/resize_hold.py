"""Deferred redraws on resize: the views whose picture is expensive to redraw at a new size (the
matplotlib canvas, the pyvistaqt/VTK 3D views) keep showing their old picture, stretched, while
a window is resized, and redraw at the new size in an event-loop turn of their own once the
resizes have stopped for :data:`HOLD_MS`.

Why (issue 21): maximising the workspace to 2560 x 1440 paid, in one turn, Qt's relayout and
the whole window's repaint and composition (with software OpenGL: new, larger buffers and
textures), a matplotlib draw (tick-label layout, ~100 ms) and the 3D view's new framebuffers
plus a VTK render (~100 ms). With the holds the resize turn pays only Qt's share; each view's
redraw runs later, in a turn of its own. A drag-resize redraws each view once, when it pauses.

:class:`ResizeHold` is the one mechanism: a widget's ``resizeEvent`` hands the event to its
hold instead of the base class, and its paint shows the old picture while :attr:`~ResizeHold.held`.
:func:`canvas_class` is matplotlib's Qt canvas with a hold; ``gui/plotter3d.py`` gives the 3D
views' interactor one. :func:`release_all` applies every pending hold at once (before a
screenshot or a grab).

GUI thread only.
"""

from __future__ import annotations

import functools
import weakref
from typing import Callable

from PySide6.QtCore import QObject, QSize, QTimer
from PySide6.QtGui import QResizeEvent
from PySide6.QtWidgets import QWidget

#: quiet time after the last resize before a held view redraws at its new size
HOLD_MS = 80

_HOLDS: "weakref.WeakSet[ResizeHold]" = weakref.WeakSet()


class ResizeHold(QObject):
    """Holds ``widget``'s own resize handling ``apply(event)`` (the base class's ``resizeEvent``:
    new buffers at the new size and a redraw) until no resize came for :data:`HOLD_MS`, then
    applies it once with the size the widget has then. A resize while ``ready()`` is false (no
    picture yet) or while the widget is hidden is applied at once."""

    def __init__(self, widget: QWidget, apply: Callable[[QResizeEvent], None], ready: Callable[[], bool],
                 hold_ms: int = HOLD_MS, complete: Callable[[], None] | None = None) -> None:
        """``complete``: finishes now what ``apply`` left for a later turn (for :func:`release_all`)."""
        super().__init__(widget)
        self._widget = widget
        self._apply = apply
        self._complete = complete
        self._ready = ready
        self._old: QSize | None = None  # the size the widget's picture was made for, while held
        self._timer = QTimer(self)
        self._timer.setSingleShot(True)
        self._timer.setInterval(hold_ms)
        self._timer.timeout.connect(self.release)
        _HOLDS.add(self)

    @property
    def held(self) -> bool:
        """A resize is waiting: the widget's picture is the one made for its old size."""
        return self._old is not None

    @property
    def old_size(self) -> QSize:
        """The size the widget's picture was made for (its size now when nothing is held)."""
        return QSize(self._old) if self._old is not None else self._widget.size()

    def resize_event(self, event: QResizeEvent) -> None:
        """Call from the widget's ``resizeEvent`` in place of the base class's."""
        if not self._widget.isVisible() or not self._ready():
            self._old = None
            self._timer.stop()
            self._apply(event)
            return
        if self._old is None:
            self._old = QSize(event.oldSize())
        self._timer.start()

    def release(self) -> None:
        """Apply the held resize now (nothing if none is held)."""
        self._timer.stop()
        if self._old is None:
            return
        old, self._old = self._old, None
        if self._widget.size() != old:  # resized and back (a scroll bar came and went): as it was
            self._apply(QResizeEvent(self._widget.size(), old))


def release_all() -> None:
    """Apply every held resize now (before grabbing a window: each view then shows its picture
    at its size)."""
    for hold in list(_HOLDS):
        try:
            hold.release()
            if hold._complete is not None:
                hold._complete()
        except RuntimeError:  # its widget was deleted (the C++ side)
            pass


@functools.cache
def canvas_class() -> type:
    """matplotlib's ``FigureCanvasQTAgg`` with a :class:`ResizeHold`: while held, its paint
    draws the last rendered picture stretched to the widget (matplotlib's own paint would draw
    the figure at the new size, layout and text included). Made on first use: matplotlib is
    imported lazily."""
    from matplotlib.backends.backend_qtagg import FigureCanvasQTAgg
    from PySide6.QtGui import QImage, QPainter

    class Canvas(FigureCanvasQTAgg):
        def __init__(self, figure=None):
            super().__init__(figure)
            self.resize_hold = ResizeHold(self, lambda e: FigureCanvasQTAgg.resizeEvent(self, e),
                                          ready=lambda: getattr(self, "renderer", None) is not None)

        def resizeEvent(self, event) -> None:  # noqa: N802 - Qt override
            self.resize_hold.resize_event(event)

        def paintEvent(self, event) -> None:  # noqa: N802 - Qt override
            if not self.resize_hold.held:
                super().paintEvent(event)
                return
            # the renderer still has the old size (the figure's size changes when the hold ends)
            buf = memoryview(self.buffer_rgba())
            img = QImage(buf, buf.shape[1], buf.shape[0], QImage.Format.Format_RGBA8888)
            p = QPainter(self)
            p.drawImage(self.rect(), img)
            p.end()

    return Canvas
