"""3D view of the calibrated rig: camera frusta (one colour per camera; the legend is a label
beside the view, :func:`legend_html`) and board poses.

The pyvistaqt plotter is created lazily (first time the page is shown) and only touched on the
GUI thread; the wizard hands it plain arrays. A scene is drawn in stages over several event-loop
turns (``gui/plotter3d.py``). For screenshots the rendered frame is copied
into a label on top of the OpenGL widget, because grabbing a native GL window gives black.
"""

from __future__ import annotations

import html

import numpy as np
from PySide6.QtCore import Qt
from PySide6.QtWidgets import QLabel, QStackedLayout, QWidget

from ..plotter3d import Stages, changing, first_frame_held, make_plotter, release_first_frame
from .widgets import camera_colour, qpixmap


def frustum_lines(cam, depth: float) -> tuple[np.ndarray, np.ndarray]:
    """Frustum of ``cam`` (a core Camera) in the rig frame: points (5, 3) (centre + 4 image corners
    at ``depth`` metres along the axis) and VTK line cells."""
    w, h = cam.width, cam.height
    uv = np.array([[-0.5, -0.5], [w - 0.5, -0.5], [w - 0.5, h - 0.5], [-0.5, h - 0.5]])
    d_cam = cam.rays_cam(uv) * depth  # z = 1 rays scaled to the depth
    pts_cam = np.vstack([np.zeros((1, 3)), d_cam])
    pts = cam.to_rig(pts_cam)
    lines = np.array([2, 0, 1, 2, 0, 2, 2, 0, 3, 2, 0, 4, 2, 1, 2, 2, 2, 3, 2, 3, 4, 2, 4, 1])
    return pts, lines


BOARD_COLOUR = "#c8c8c8"


def legend_html(names: list[str]) -> str:
    """The view's legend as rich text for a label beside it: a swatch of each camera's frustum
    colour (``names`` in the rig's camera order, as :meth:`FrustaView.set_scene` colours them)
    and the board poses'. Not drawn in the scene: the optical centres are centimetres apart, and
    a legend box in the scene is a fixed share of the view (a narrow view cut the names)."""
    sw = "<span style='color:{c}; font-size: 14pt;'>&#9632;</span>&nbsp;{n}"
    items = [sw.format(c=camera_colour(i), n=html.escape(n)) for i, n in enumerate(names)]
    items.append(sw.format(c="#9a9a9a", n="board poses (grey)"))
    return "Legend: " + " &nbsp; ".join(items)


class FrustaView(QWidget):
    def __init__(self, parent=None) -> None:
        super().__init__(parent)
        self._stack = QStackedLayout(self)
        self._stack.setStackingMode(QStackedLayout.StackingMode.StackOne)
        self._placeholder = QLabel("3D view: shown once the rig is calibrated")
        self._placeholder.setAlignment(Qt.AlignmentFlag.AlignCenter)
        self._placeholder.setStyleSheet("background: #20242a; color: #dddddd;")
        self._stack.addWidget(self._placeholder)
        self._snapshot = QLabel()
        self._snapshot.setAlignment(Qt.AlignmentFlag.AlignCenter)
        self._snapshot.setStyleSheet("background: #20242a;")
        self._snapshot.setScaledContents(True)
        self._stack.addWidget(self._snapshot)
        self.plotter = None
        self._creating = False
        self._scene = None
        self.error: str | None = None
        self.n_frusta = 0
        self.n_boards = 0
        self._n = (0, 0)
        self._frusta: list = []
        self._axes = False
        self._stages = Stages(self)

    def _ensure_plotter(self) -> bool:
        if self.plotter is not None:
            return True
        if self.error is not None or self._creating:
            return False
        # constructing the GL widget processes events: a nested show must not build a second one
        self._creating = True
        try:
            plotter = make_plotter(self)
            plotter.set_background("#20242a")
            # not the current widget yet (hidden): its first frame is drawn in a later event-loop turn
            self._stack.insertWidget(0, plotter.interactor)
            self._stack.setCurrentWidget(self._placeholder)
            self.plotter = plotter
            self._axes = False
        except Exception as e:  # no OpenGL: keep the page usable, say why the 3D view is missing
            self.error = f"3D view unavailable ({type(e).__name__}: {e})"
            self._placeholder.setText(self.error)
            return False
        finally:
            self._creating = False
        return True

    @property
    def building(self) -> bool:
        return self._stages.running

    def set_scene(self, cameras: list, boards: list[np.ndarray], depth: float | None = None) -> None:
        """``cameras`` core Cameras (rig frame); ``boards`` (4, 3) rig-frame outlines of board poses."""
        self._scene = (cameras, boards, depth)
        if not self.isVisible():
            return  # drawn when shown
        self._draw()

    def showEvent(self, event) -> None:  # noqa: N802
        super().showEvent(event)
        if self._scene is not None:
            self._draw()

    def _draw(self) -> None:
        """Draw the pending scene over several event-loop turns (plotter3d.Stages: with software
        OpenGL the plotter, its first frame and the first frame of each kind of actor each take
        ~100 ms): the plotter (hidden), the widget shown (background only), VTK's first frame,
        boards and frusta, axes (the legend is a label under the view: :func:`legend_html`)."""
        if self._scene is None:
            return

        def plotter() -> None:
            if not self._ensure_plotter():
                self._stages.cancel()

        def show_widget() -> None:
            self._stack.setCurrentWidget(self.plotter.interactor)

        def first_frame() -> None:
            release_first_frame(self.plotter)

        steps = [] if self.plotter is not None else [plotter]
        if self.plotter is None or self._stack.currentWidget() is not self.plotter.interactor:
            steps.append(show_widget)
        if self.plotter is None or first_frame_held(self.plotter):
            steps.append(first_frame)
        self._stages.start(steps + [self._draw_scene, self._draw_frusta, self._draw_axes])

    def _draw_scene(self) -> None:
        """The board poses and the camera placed (the frusta follow in the next turn: the first
        frame of each kind of actor compiles its shaders)."""
        import pyvista as pv

        if self._scene is None:
            return
        cameras, boards, depth = self._scene
        self._scene = None  # drawn; redraw only on new data
        centres = np.array([c.center_rig for c in cameras]) if cameras else np.zeros((1, 3))
        if depth is None:
            dists = [float(np.linalg.norm(b.mean(axis=0) - centres.mean(axis=0))) for b in boards]
            depth = 0.4 * float(np.median(dists)) if dists else 0.15
        self._frusta = [(frustum_lines(cam, depth), camera_colour(i)) for i, cam in enumerate(cameras)]
        with changing(self.plotter) as p:
            p.clear_actors()
            if boards:  # one actor for all boards: each actor costs the first (software GL) render time
                pts = np.concatenate([np.asarray(b, float) for b in boards])
                faces = np.concatenate([[4, 4 * i, 4 * i + 1, 4 * i + 2, 4 * i + 3] for i in range(len(boards))])
                p.add_mesh(pv.PolyData(pts, faces=faces), color=BOARD_COLOUR, opacity=0.35, show_edges=True,
                           edge_color="#f0f0f0", render=False)
            # a side view of the rig (rig frame: z forward = down towards the ground): rig at the top,
            # boards below it
            p.renderer.view_vector((1.0, 0.45, -0.55), viewup=(0, 0, -1), render=False)
            p.renderer.reset_camera(render=False)
        self._n = (len(cameras), len(boards))

    def _draw_frusta(self) -> None:
        import pyvista as pv

        with changing(self.plotter) as p:
            for (pts, lines), colour in self._frusta:
                p.add_mesh(pv.PolyData(pts, lines=lines), color=colour, line_width=3, render=False)
            p.renderer.reset_camera(render=False)  # boards and frusta

    def _draw_axes(self) -> None:
        with changing(self.plotter) as p:
            if not self._axes:
                p.add_axes()
                self._axes = True
        self.n_frusta, self.n_boards = self._n  # the scene is complete

    def prepare_screenshot(self) -> None:
        """Copy the rendered frame into a label on top (native GL windows grab as black)."""
        if self.plotter is None or not self.isVisible():
            return
        if self._scene is not None:
            self._draw()
        self._stages.finish()
        release_first_frame(self.plotter)
        try:
            self.plotter.render()
            img = self.plotter.screenshot(return_img=True)
        except Exception:
            return
        if img is None:
            return
        self._snapshot.setPixmap(qpixmap(np.ascontiguousarray(img[:, :, :3])))
        self._stack.setCurrentWidget(self._snapshot)

    def close_plotter(self) -> None:
        self._stages.cancel()
        if self.plotter is not None:
            try:
                self.plotter.close()
            except Exception:
                pass
            self.plotter = None
