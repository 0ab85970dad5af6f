"""3D view (pyvistaqt): the multimodal point cloud coloured by any modality, the object and
uncertainty meshes, and point picking that reads out every modality at the picked point.

The plotter is created lazily (the first time the view is shown) and touched only on the GUI
thread; workers hand over numpy arrays (:class:`~.model.Cloud`). A new scene is built in stages
over several event-loop turns (:meth:`CloudView.show_staged`, ``gui/plotter3d.py``).
"""

from __future__ import annotations

import numpy as np
from PySide6.QtCore import Qt
from PySide6.QtWidgets import (
    QCheckBox, QComboBox, QHBoxLayout, QLabel, QSpinBox, QSplitter, QVBoxLayout, QWidget,
)

from ..plotter3d import Stages, first_frame_held, make_plotter, release_first_frame, repaint
from ...models.layers import Cloud

MESH_COLOURS = {"object mesh": "#3c9a3c", "uncertainty mesh": "#d040d0"}


#: the last line of the read-out pane
PICK_HINT = "Left-click a point to read all its values; a second click adds its distance to the first."


class CloudView(QWidget):
    def __init__(self, parent: QWidget | None = None):
        super().__init__(parent)
        self.cloud: Cloud | None = None
        self.meshes: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        self.plotter = None
        self._poly = None
        self._step = 1  # the cloud actor shows every _step-th point (> 1 while a staged build previews)
        self._axes = False
        self._stages = Stages(self)
        self._mesh_actors: dict[str, object] = {}
        self._tree = None
        self._dirty = False  # the scene needs rebuilding before the next render
        self.picked_index: int | None = None
        self._creating = False

        self.colour = QComboBox()
        self.colour.setToolTip("modality that colours the points")
        self.point_size = QSpinBox()
        self.point_size.setRange(1, 12)
        self.point_size.setValue(3)
        self.mesh_boxes: dict[str, QCheckBox] = {}
        top = QHBoxLayout()
        top.addWidget(QLabel("Colour by"))
        top.addWidget(self.colour)
        self.point_size.setSuffix(" px")
        self.point_size.setToolTip("drawn size of the points on the screen (pixels); positions and distances "
                                   "in the read-out are in millimetres")
        top.addWidget(QLabel("Point size"))
        top.addWidget(self.point_size)
        for name in MESH_COLOURS:
            cb = QCheckBox(f"Show {name}")
            cb.setEnabled(False)
            cb.toggled.connect(self._mesh_toggled)
            self.mesh_boxes[name] = cb
            top.addWidget(cb)
        top.addStretch(1)

        self.host = QWidget()
        self.host_layout = QVBoxLayout(self.host)
        self.host_layout.setContentsMargins(0, 0, 0, 0)
        self.placeholder = QLabel("No point cloud yet.")
        self.placeholder.setAlignment(Qt.AlignmentFlag.AlignCenter)
        self.host_layout.addWidget(self.placeholder)
        self.info = QLabel("")
        self.info.setTextInteractionFlags(Qt.TextInteractionFlag.TextSelectableByMouse)
        self.info.setAlignment(Qt.AlignmentFlag.AlignTop | Qt.AlignmentFlag.AlignLeft)
        self.info.setWordWrap(True)
        self.info.setMinimumWidth(240)
        self.info.setStyleSheet("font-family: monospace; font-size: 11px;")
        split = QSplitter(Qt.Orientation.Horizontal)
        split.addWidget(self.host)
        split.addWidget(self.info)
        split.setStretchFactor(0, 1)
        split.setChildrenCollapsible(False)
        lay = QVBoxLayout(self)
        lay.setContentsMargins(2, 2, 2, 2)
        lay.addLayout(top)
        from .image_views import ColourBar

        self.bar = ColourBar()  # the colouring layer's map and limits, as in the 2D views (hidden for RGB)
        self.bar.setToolTip("colour map and limits of the layer that colours the points")
        lay.addWidget(self.bar)
        lay.addWidget(split, 1)
        self.colour.currentIndexChanged.connect(self._recolour)
        self.point_size.valueChanged.connect(self._resize_points)

    # ------------------------------------------------------------------ data
    def set_cloud(self, cloud: Cloud | None, meshes: dict[str, tuple[np.ndarray, np.ndarray]] | None = None,
                  default: str | None = None, note: str = "") -> None:
        """``cloud`` points and per-modality colours; ``meshes[name]`` = (vertices (V, 3), triangles (T, 3))."""
        self.cloud = cloud
        self.meshes = {k: v for k, v in (meshes or {}).items() if v is not None and len(v[1])}
        keep = self.colour.currentText()
        self.colour.blockSignals(True)
        self.colour.clear()
        if cloud is not None:
            self.colour.addItems(list(cloud.colours))
            if keep in cloud.colours:
                self.colour.setCurrentText(keep)
            elif default in cloud.colours:
                self.colour.setCurrentText(default)
        self.colour.blockSignals(False)
        for name, cb in self.mesh_boxes.items():
            cb.setEnabled(name in self.meshes)
            if name not in self.meshes:
                cb.setChecked(False)
        self._tree = None
        self.picked_index = None
        n = 0 if cloud is None else len(cloud.points)
        # the hint at the end of the read-out pane, wrapped (in the tool bar it was cut to a
        # stray stroke at 1280 px)
        self.info.setText((note + "\n\n" if note else "") + f"{n:,} points.\n\n{PICK_HINT}"
                          if cloud is not None else note)
        self._dirty = True
        if self.isVisible():
            self.show_staged()

    # ------------------------------------------------------------------ plotter
    # the first frame of a new scene shows every k-th point, at most this many (a quick first
    # picture; the full cloud and the meshes follow in the next event-loop turns)
    PREVIEW_POINTS = 20000

    @property
    def building(self) -> bool:
        """A staged build (:meth:`show_staged`) is still adding parts of the scene."""
        return self._stages.running

    def ensure_plotter(self) -> None:
        if self.plotter is not None or self._creating:
            return
        # constructing the GL widget processes events; a nested render request must not build a second one
        self._creating = True
        try:
            # without a parent: placed in the window by attach_gl_widget, in a turn of its own
            plotter = make_plotter(None)
        finally:
            self._creating = False
        self.plotter = plotter
        self._axes = False
        # hidden until show_gl_widget, which paints the background only; VTK's first frame
        # (long with software GL) follows in first_frame, each in an event-loop turn of its own
        plotter.interactor.hide()
        # a plain background: a gradient is one more shader to compile in the first frame
        self.plotter.set_background("#22272e")
        try:
            self.plotter.enable_point_picking(callback=self._picked, show_message=False, left_clicking=True,
                                              show_point=True, color="red", point_size=12)
        except TypeError:  # older pyvista without some keywords
            self.plotter.enable_point_picking(callback=self._picked, show_message=False)
        self._dirty = True

    def attach_gl_widget(self) -> None:
        """Put the (hidden) GL widget into the window. The first one makes Qt re-create the
        window's native surface for OpenGL composition (long with software OpenGL), so
        this is a stage of its own, apart from the plotter's constructor."""
        w = self.plotter.interactor if self.plotter is not None else None
        if w is not None and w.parent() is not self.host:
            self.host_layout.addWidget(w)
            w.hide()
            self.host.destroyed.connect(w.close)  # what pyvistaqt does for a plotter made with a parent

    def show_gl_widget(self) -> None:
        self.attach_gl_widget()
        if self.plotter is not None and self.plotter.interactor.isHidden():
            self.placeholder.hide()
            self.plotter.interactor.show()

    def first_frame(self) -> None:
        release_first_frame(self.plotter)

    def render_now(self) -> None:
        """Build the whole scene now, if needed, and render (GUI thread; before a screenshot)."""
        if self.cloud is None and not self.meshes:
            return
        self._stages.finish()
        self.ensure_plotter()
        if self.plotter is None:
            return
        self.show_gl_widget()
        self.first_frame()
        self._add_axes()
        if self._dirty:
            self._rebuild()
        self.plotter.render()

    def show_staged(self) -> None:
        """Show the scene (the tab was shown, or a new cloud arrived while it is shown), built over
        several event-loop turns so that the GUI thread never stalls: the plotter (its GL widget),
        the widget shown (background only), VTK's first frame, a preview of the cloud (every k-th
        point) and the camera, the orientation axes, the full cloud, the meshes -- each step
        followed by a repaint (plotter3d.Stages)."""
        if self.cloud is None and not self.meshes:
            return
        steps: list = []
        if self.plotter is None:
            steps.append(self.ensure_plotter)
        if self.plotter is None or self.plotter.interactor.parent() is not self.host:
            steps.append(self.attach_gl_widget)
        if self.plotter is None or self.plotter.interactor.isHidden():
            steps.append(self.show_gl_widget)  # the background colour only
        if self.plotter is None or first_frame_held(self.plotter):
            steps.append(self.first_frame)
        if self._dirty or self.plotter is None:
            n = 0 if self.cloud is None else len(self.cloud.points)
            k = max(1, -(-n // self.PREVIEW_POINTS))

            def preview_cloud() -> None:
                self._begin_scene()
                self._add_cloud(k)
                self._place_camera()
                repaint(self.plotter)

            def axes() -> None:
                self._add_axes()
                repaint(self.plotter)

            def full_cloud() -> None:
                self._add_cloud(1)
                repaint(self.plotter)

            def meshes() -> None:
                self._add_meshes()
                self._dirty = False
                repaint(self.plotter)

            steps += [preview_cloud, axes] + ([full_cloud] if k > 1 else []) + [meshes]
        else:
            steps.append(lambda: repaint(self.plotter))
        self._stages.start(steps)

    def _add_axes(self) -> None:
        if self.plotter is not None and not self._axes:
            self.plotter.add_axes(color="white")  # orientation of the rig frame (x right, y down, z forward)
            self._axes = True

    def _rebuild(self) -> None:
        self._begin_scene()
        self._add_cloud(1)
        self._add_meshes()
        self._place_camera()
        self._dirty = False

    def _begin_scene(self) -> None:
        self.plotter.clear_actors()  # (no render: the caller repaints once the scene is built)
        self._mesh_actors.clear()
        self._poly = None

    def _add_cloud(self, step: int) -> None:
        """The cloud actor with every ``step``-th point (1: all), replacing the previous one."""
        import pyvista as pv

        if self.cloud is None or not len(self.cloud.points):
            return
        poly = pv.PolyData(np.ascontiguousarray(self.cloud.points[::step], dtype=np.float32))
        poly.point_data["colour"] = self._colours()[::step]
        self._poly, self._step = poly, step
        self.plotter.add_mesh(poly, scalars="colour", rgb=True, point_size=self.point_size.value(),
                              render_points_as_spheres=False, name="cloud", pickable=True, render=False)

    def _add_meshes(self) -> None:
        import pyvista as pv

        for name, (verts, tris) in self.meshes.items():
            faces = np.hstack([np.full((len(tris), 1), 3, np.int64), np.asarray(tris, np.int64)]).ravel()
            mesh = pv.PolyData(np.asarray(verts, np.float32), faces)
            actor = self.plotter.add_mesh(mesh, color=MESH_COLOURS[name], opacity=0.35, name=name, pickable=False,
                                          show_edges=False, render=False)
            actor.SetVisibility(self.mesh_boxes[name].isChecked())
            self._mesh_actors[name] = actor

    def _place_camera(self) -> None:
        if not self._dirty_camera_kept():
            self._reset_camera()

    def _dirty_camera_kept(self) -> bool:
        return getattr(self, "_camera_set", False)

    def _reset_camera(self) -> None:
        """An oblique view from above and to the side, "up" towards the rig (the rig frame has
        y down and z towards the ground), so that the heights of leaves are visible."""
        pts = self.cloud.points if self.cloud is not None and len(self.cloud.points) else None
        if pts is None:
            self.plotter.renderer.reset_camera(render=False)  # (Plotter.reset_camera renders, whatever it is told)
            return
        c = np.nanmedian(pts, axis=0).astype(float)
        ext = float(np.nanmax(np.nanpercentile(pts, 98, axis=0) - np.nanpercentile(pts, 2, axis=0)))
        d = np.array([0.3, 0.6, -1.0])
        d /= np.linalg.norm(d)
        up = np.array([0.0, 0.0, -1.0])
        up -= d * (up @ d)
        self.plotter.camera_position = [tuple(c + d * 2.0 * max(ext, 0.05)), tuple(c), tuple(up / np.linalg.norm(up))]
        self.plotter.renderer.reset_camera(render=False)  # keeps the direction, fits the whole cloud
        self.plotter.camera.zoom(1.15)
        self._camera_set = True

    def _colours(self) -> np.ndarray:
        name = self.colour.currentText()
        if self.cloud is None or name not in self.cloud.colours:
            return np.full((0 if self.cloud is None else len(self.cloud.points), 3), 200, np.uint8)
        return np.ascontiguousarray(self.cloud.colours[name], dtype=np.uint8)

    def _recolour(self) -> None:
        if self._poly is not None:
            self._poly.point_data["colour"] = self._colours()[::self._step]
            repaint(self.plotter)

    def _resize_points(self, v: int) -> None:
        if self.plotter is not None and self._poly is not None:
            actor = self.plotter.actors.get("cloud")
            if actor is not None:
                actor.GetProperty().SetPointSize(v)
                repaint(self.plotter)

    def _mesh_toggled(self) -> None:
        for name, actor in self._mesh_actors.items():
            actor.SetVisibility(self.mesh_boxes[name].isChecked())
        repaint(self.plotter)

    # ------------------------------------------------------------------ picking
    def _picked(self, point) -> None:
        if point is None:
            return
        self.pick(np.asarray(point, dtype=np.float64))

    def pick(self, xyz: np.ndarray) -> int | None:
        """Show the values of the cloud point nearest to ``xyz`` (3,); returns its index."""
        if self.cloud is None or not len(self.cloud.points):
            return None
        if self._tree is None:
            from scipy.spatial import cKDTree

            self._tree = cKDTree(self.cloud.points)
        _, i = self._tree.query(np.asarray(xyz, dtype=np.float64).reshape(3))
        previous, self.picked_index = self.picked_index, int(i)
        self.info.setText(self.cloud.point_text(int(i), previous) + f"\n\n{PICK_HINT}")  # distance to the last pick
        return int(i)

    def show_point(self, i: int) -> None:
        """Read out cloud point ``i`` (no KD tree needed: for a known target pixel)."""
        self.picked_index = int(i)
        self.info.setText(self.cloud.point_text(int(i)) + f"\n\n{PICK_HINT}")

    # ------------------------------------------------------------------ the workspace's session
    needs = "cloud"

    def bind(self, session) -> "CloudView":
        """Show ``session``'s point cloud (registered, or a Plant3DImageReg plant's own) and meshes."""

        def refresh() -> None:
            if session.plant is not None:
                p = session.plant
                self.set_cloud(session.cloud, None, default="depth",
                               note=f"{p.plant}: depth camera frame, nominal intrinsics (not calibrated).")
                return
            r = session.result
            note = f"Target {r.target}: object-mesh hits in the rig frame." if r is not None else ""
            self.set_cloud(session.cloud, session.meshes, default=session.colour_layer(), note=note)

        def bar() -> None:
            name = self.colour.currentText()
            L = session.layer(name) or session.layer(name, registered=False)
            if self.cloud is None or L is None:
                self.bar.set_bar(None, None)
            else:
                self.bar.set_bar(*session.colour_bar(L))

        def display(name: str) -> None:
            if self.cloud is not None and self.colour.currentText() == name:
                self._recolour()
                bar()

        def cursor() -> None:  # the 2D cursor's object point, when the session moved it to one
            c = session.cursor
            if c is None or c[0] != "target" or self.cloud is None or session.result is None or \
                    self.picked_index is not None:
                return
            flat = c[1] * session.result.shape[1] + c[2]
            i = int(np.searchsorted(self.cloud.pixels, flat))
            if i < len(self.cloud.pixels) and self.cloud.pixels[i] == flat:
                self.show_point(i)

        session.events.result.connect(refresh)
        session.events.result.connect(bar)
        self.colour.currentIndexChanged.connect(lambda _i: bar())
        session.events.display.connect(display)
        session.events.cursor.connect(cursor)
        return self

    # ------------------------------------------------------------------ teardown
    # -- the workspace's view hooks (views.py)
    def on_shown(self) -> None:
        self.show_staged()  # over several event-loop turns: no stall

    def prepare_screenshot(self) -> None:
        self.render_now()

    def view_rgb(self):
        """The rendered scene at the window's size, (H, W, 3) uint8; None before there is one."""
        import numpy as np

        self.render_now()
        if self.plotter is None:
            return None
        return np.ascontiguousarray(np.asarray(self.plotter.screenshot(None, return_img=True))[..., :3])

    def shutdown(self) -> None:
        self.close_plotter()

    def close_plotter(self) -> None:
        self._stages.cancel()
        if self.plotter is not None:
            try:
                self.plotter.close()
            finally:
                self.plotter = None
