"""What the 3D views (the workspace's point cloud, the wizard's frusta) share: a pyvistaqt plotter
that is cheap to draw with software OpenGL, and a staged build that keeps every GUI-thread slice
short.

On the 3D tab's first show (Mesa llvmpipe; per-step times in docs/workspace.md): the render
window's default 8x multi-sampling costs most of a frame's CPU, every ``plotter.render()`` is followed by a second render
when the widget repaints (pyvistaqt's ``paintGL`` always renders), and the first frame of each
new kind of actor compiles its shaders. So the views ask for no multi-sampling, change the scene
with ``render=False`` and let one repaint draw it (:func:`repaint`), and build a new scene in
:class:`Stages`: one step per event-loop turn, a repaint after each. A new plotter draws VTK's
first frame only when :func:`release_first_frame` is called (its first paints, during the
widget's ``show()``, fill the background colour), so that showing the widget (with Qt's switch of
the window to OpenGL composition) and VTK's first frame take a turn each.

GUI thread only (pyvistaqt: the render window is touched only there).
"""

from __future__ import annotations

import functools
from contextlib import contextmanager
from typing import Any, Callable, Iterator

from PySide6.QtCore import QObject, QTimer
from PySide6.QtWidgets import QWidget

# gap between two stages: the repaint of one stage and the event loop's other work run in between
STAGE_GAP_MS = 15


@functools.cache
def _interactor_class() -> type:
    """pyvistaqt's ``QtInteractor`` whose paints fill the background colour, without a VTK
    render, while ``first_frame_held`` (see :func:`release_first_frame`), and whose resizes are
    held (``gui/resize_hold.py``): while a window is resized its paints show the last frame,
    stretched, and the new framebuffers and the render at the new size wait for a turn of
    their own. Made on first use: pyvistaqt is imported lazily."""
    from PySide6.QtCore import QRect, QSize
    from PySide6.QtGui import QResizeEvent
    from pyvistaqt import QtInteractor

    from .resize_hold import ResizeHold

    class Interactor(QtInteractor):
        first_frame_held = True
        _fbo_size = None  # QSize of the widget's framebuffer while a two-turn resize is under way
        _drawn = False  # VTK has drawn a frame in the widget's paint

        def __init__(self, *args, **kwargs) -> None:
            super().__init__(*args, **kwargs)
            # pyvistaqt's QOpenGLWidget interactor renders into framebuffers of its own (an
            # older, native-window one has no _ctx and resizes at once)
            self.resize_hold = ResizeHold(self, self._apply_resize,
                                          ready=lambda: getattr(self, "_ctx", None) is not None
                                          and not self.first_frame_held, complete=self._finish_resize)

        def _apply_resize(self, event) -> None:
            """The held resize, in two turns. With software OpenGL, VTK's first render at a new
            size (its new framebuffers: 30-200 ms at 2560 x 1440) and the window's composition
            of the new frame (60-150 ms) added up to 250-400 ms in one turn. So VTK renders at
            the new size now, into its own framebuffers, while the widget keeps its old
            framebuffer (showing the new frame, stretched); the widget's new framebuffer, a
            render and the composition follow in a later turn."""
            if not hasattr(self, "_blit") or getattr(self, "_ctx", None) is None or not self.isVisible() \
                    or not self._drawn:  # hidden, or VTK has not drawn in the widget yet: at once, as Qt
                # does (VTK's first frame rendered outside the widget's paint left it black)
                self._fbo_size = None
                QtInteractor.resizeEvent(self, event)
                return
            if self._fbo_size is None:
                self._fbo_size = QSize(event.oldSize())
            # a turn apart from the other held views' redraws (released by the same resizes)
            QTimer.singleShot(STAGE_GAP_MS, self._render_at_new_size)

        def _render_at_new_size(self) -> None:
            try:
                if self._fbo_size is None or self.resize_hold.held:
                    return
                rw = self.GetRenderWindow()
                if rw is None or getattr(self, "_ctx", None) is None:  # closed meanwhile
                    self._fbo_size = None
                    return
                self.makeCurrent()
                self._in_paint = True  # the render's frame event asks for no repaint
                try:
                    self.resizeGL(self.width(), self.height())
                    rw.Render()
                finally:
                    self._in_paint = False
                QTimer.singleShot(STAGE_GAP_MS, self._finish_resize)
            except RuntimeError:  # deleted meanwhile
                pass

        def _finish_resize(self) -> None:
            try:
                if self._fbo_size is None or self.resize_hold.held:  # held again: applied later
                    return
                old, self._fbo_size = self._fbo_size, None
                if self.GetRenderWindow() is None:  # closed meanwhile
                    return
                QtInteractor.resizeEvent(self, QResizeEvent(self.size(), old))
                self.update()  # the window composes the new framebuffer
            except RuntimeError:  # deleted meanwhile
                pass

        def resizeEvent(self, event) -> None:  # noqa: N802 - Qt override
            self.resize_hold.resize_event(event)

        def paintGL(self) -> None:  # noqa: N802 - Qt override
            if (self.resize_hold.held or self._fbo_size is not None) and hasattr(self, "_blit"):
                # framebuffers and render window keep their old size: show VTK's last frame
                # again (Qt may have discarded the widget's framebuffer), no render
                rw = self.GetRenderWindow()
                st = rw.GetState()
                st.Reset()
                st.Push()
                # into the framebuffer's old size (VTK's frame may already have the new one)
                fbo = self._fbo_size or self.resize_hold.old_size
                dpr = self.devicePixelRatioF()
                self._blit(self.defaultFramebufferObject(),
                           QRect(0, 0, max(1, round(fbo.width() * dpr)), max(1, round(fbo.height() * dpr))))
                st.Pop()
                return
            if not self.first_frame_held:
                super().paintGL()
                self._drawn = True
                return
            ctx = self.context()
            if ctx is None:
                return
            r, g, b = self.background_color.float_rgba[:3]
            f = ctx.functions()
            f.glClearColor(r, g, b, 1.0)
            f.glClear(0x4000)  # GL_COLOR_BUFFER_BIT

    return Interactor


def make_plotter(parent: QWidget) -> Any:
    """A ``pyvistaqt.QtInteractor`` child of ``parent``: no auto-update (pyvistaqt's default
    re-renders 5 times a second for ever; the views repaint when their scene changes and the
    interactor renders while the user rotates) and no multi-sampling (with software OpenGL it
    tripled the cost of a frame; points and thin lines look the same without it). Its widget
    shows the background colour until :func:`release_first_frame`."""
    return _interactor_class()(parent, auto_update=False, multi_samples=0)


def first_frame_held(plotter: Any) -> bool:
    """``plotter``'s widget still paints only its background (:func:`release_first_frame`)."""
    return bool(getattr(plotter, "first_frame_held", False))


def release_first_frame(plotter: Any) -> None:
    """Let ``plotter``'s widget draw the scene from now on, and repaint it. VTK's first frame in a
    new render window (GL state, framebuffers, the first shaders: long with software OpenGL)
    then runs in an event-loop turn of its own instead of inside the widget's ``show()``."""
    if plotter is not None and first_frame_held(plotter):
        plotter.first_frame_held = False
        repaint(plotter)


def repaint(plotter: Any) -> None:
    """Have ``plotter``'s widget draw the current scene once, at the next paint (not now: a
    ``plotter.render()`` renders now *and* again when the widget repaints)."""
    if plotter is not None:
        plotter.interactor.update()


@contextmanager
def changing(plotter: Any) -> Iterator[Any]:
    """Change ``plotter``'s scene without rendering (pyvista renders after many calls, e.g.
    ``Plotter.reset_camera`` even when told ``render=False``), then :func:`repaint` once."""
    old = plotter.suppress_rendering
    plotter.suppress_rendering = True
    try:
        yield plotter
    finally:
        plotter.suppress_rendering = old
        repaint(plotter)


class Stages(QObject):
    """Runs a list of steps, one per event-loop turn (each should take well under 200 ms of GUI
    thread), ``STAGE_GAP_MS`` apart so that the repaint a step asked for and other events run in
    between. :meth:`start` replaces a run still pending; :meth:`finish` runs what is left at once
    (before a screenshot). A step that raises ends the run."""

    def __init__(self, parent: QObject | None = None, gap_ms: int = STAGE_GAP_MS) -> None:
        super().__init__(parent)
        self._steps: list[Callable[[], Any]] = []
        self._timer = QTimer(self)
        self._timer.setSingleShot(True)
        self._timer.setInterval(gap_ms)
        self._timer.timeout.connect(self._next)
        self.timings: list[tuple[str, float]] = []  # (step name, ms) of the last run, for benchmarks

    @property
    def running(self) -> bool:
        return bool(self._steps)

    def start(self, steps: list[Callable[[], Any]]) -> None:
        self._steps = list(steps)
        self.timings = []
        if self._steps:
            self._timer.start()
        else:
            self._timer.stop()

    def cancel(self) -> None:
        self._steps = []
        self._timer.stop()

    def finish(self) -> None:
        self._timer.stop()
        while self._steps:
            self._run_one()

    def _run_one(self) -> None:
        import time

        step = self._steps.pop(0)
        t = time.perf_counter()
        try:
            step()
        except BaseException:
            self.cancel()
            raise
        self.timings.append((getattr(step, "__name__", "step"), (time.perf_counter() - t) * 1000.0))

    def _next(self) -> None:
        if self._steps:
            self._run_one()
        if self._steps:
            self._timer.start()
