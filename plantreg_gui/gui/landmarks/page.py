"""The landmark page: a view of :class:`~plantreg_gui.models.landmarks.LandmarkSession`.

Left: the depth camera's image (infrared), right: the chosen camera, third: the chosen camera
registered into the infrared by the current rig (blend / checkerboard / flicker). Click a point
on the left, then the same point on the right; drag a marker to move it (zoom in for sub-pixel
placement); the residual of every point is drawn next to it (red line: where the rig puts it).
The table says what depth the fit takes for each point (on the surface, snapped onto a nearer
surface, or left out; the "snap depth" switch chooses between the last two, as fit-rig does).
Fit, refine (on workers, with progress and cancel), nudge the camera's pose with keys, undo,
save. All state and computation are in the session; this widget only shows it and forwards
the user's actions.

Length: the page's layout, its three image panes and their click handling; the state is in the
Qt-free :class:`~plantreg_gui.models.landmarks.LandmarkSession`.
"""

from __future__ import annotations

import html
from pathlib import Path

import numpy as np
from PySide6.QtCore import Qt, QTimer, Signal
from PySide6.QtGui import QColor, QKeySequence, QShortcut
from PySide6.QtWidgets import (
    QAbstractItemView, QCheckBox, QComboBox, QDoubleSpinBox, QFileDialog, QFormLayout, QGroupBox, QHBoxLayout,
    QLabel, QPlainTextEdit, QProgressBar, QPushButton, QSlider, QSplitter, QTableWidget, QTableWidgetItem,
    QVBoxLayout, QWidget,
)

from ...core.camera import modality
from ...core.display.display import blend, checkerboard, default_tile, to_rgb8
from ...core.errors import PlantregError
from ...models.landmarks import LandmarkSession, OverlayImages
from ...core.progress import Reporter
from ..workers import Jobs, Worker, show_error
from ..registration.image_views import ColourBar
from ...models.layers import DEPTH, DisplaySettings, Layer, colour_bar_of, raw_layers
from .point_view import Marker, PointView


class ElideLeftCombo(QComboBox):
    """A combo box that cuts a long entry at its start ("…/recordings/01grapevine"): recording
    keys are paths, and their end names the plant; the whole key is the tooltip."""

    def displayed_text(self) -> str:
        from PySide6.QtWidgets import QStyle, QStyleOptionComboBox

        opt = QStyleOptionComboBox()
        self.initStyleOption(opt)
        rect = self.style().subControlRect(QStyle.ComplexControl.CC_ComboBox, opt,
                                           QStyle.SubControl.SC_ComboBoxEditField, self)
        return self.fontMetrics().elidedText(self.currentText(), Qt.TextElideMode.ElideLeft, max(rect.width(), 20))

    def paintEvent(self, _e) -> None:  # noqa: N802 (Qt name)
        from PySide6.QtWidgets import QStyle, QStyleOptionComboBox, QStylePainter

        p = QStylePainter(self)
        opt = QStyleOptionComboBox()
        self.initStyleOption(opt)
        opt.currentText = self.displayed_text()
        p.drawComplexControl(QStyle.ComplexControl.CC_ComboBox, opt)
        p.drawControl(QStyle.ControlElement.CE_ComboBoxLabel, opt)


#: keys of the nudge panel: key -> (kind, camera axis, sign). Rotations about the camera's own
#: axes (x right, y down, z forward), translations along them -- as OpenCalib's manual panel.
NUDGE_KEYS = {
    Qt.Key.Key_W: ("rotate", 0, +1), Qt.Key.Key_S: ("rotate", 0, -1),      # tilt
    Qt.Key.Key_A: ("rotate", 1, -1), Qt.Key.Key_D: ("rotate", 1, +1),      # pan
    Qt.Key.Key_Q: ("rotate", 2, -1), Qt.Key.Key_E: ("rotate", 2, +1),      # roll
    Qt.Key.Key_Left: ("translate", 0, -1), Qt.Key.Key_Right: ("translate", 0, +1),
    Qt.Key.Key_Up: ("translate", 1, -1), Qt.Key.Key_Down: ("translate", 1, +1),
    Qt.Key.Key_PageUp: ("translate", 2, +1), Qt.Key.Key_PageDown: ("translate", 2, -1),
}

#: the points table's columns
TABLE_COLUMNS = ("#", "residual px", "depth", "depth u, v", "camera u, v", "note")
#: what a landmark's depth check adds to its marker's label, and its table cell's background
DEPTH_MARK = {"snapped": " (depth snapped)", "left out": " (depth left out)", "no depth": " (no depth)"}
DEPTH_COLOURS = {"snapped": (255, 200, 120), "left out": (255, 150, 150), "no depth": (255, 150, 150)}


def depth_text(chk) -> str:
    """A :class:`~plantreg_gui.core.rigfit.rigfit.DepthCheck` for the table's depth column."""
    if chk.status == "ok":
        return f"{chk.z_m:.3f} m"
    if chk.status == "snapped":
        return f"{chk.z_m:.3f} m, snapped {chk.snapped_mm:.0f} mm nearer"
    if chk.status == "left out":
        return f"left out ({chk.read_m:.3f} m, behind)"
    return "no depth"


FREE_PRESETS = {
    "pose": (),
    "pose + focal": ("focal",),
    "pose + focal, principal, k1": ("focal", "principal", "k1"),
}


def shown_rgb8(s: LandmarkSession, camera: str, key: str | None = None) -> np.ndarray:
    """Camera ``camera``'s image of recording ``key`` (default the current one) as the page shows
    it (RGB8); the depth camera's is :meth:`LandmarkSession.depth_image`."""
    if camera == s.rig.depth().name:
        return to_rgb8(np.asarray(s.depth_image(key)), s.rig.depth().modality)
    return to_rgb8(np.asarray(s.camera_image(camera, key)), s.rig.camera(camera).modality)


def read_session(rig: str | Path, landmarks: str | Path | None, recordings: list[str | Path],
                 progress: Reporter) -> tuple[LandmarkSession, dict[tuple[str, str], np.ndarray]]:
    """The page's opening, for a worker: the session with every recording read, and the current
    recording's images as shown, by (recording, camera) (a hyperspectral cube's false colour is
    too slow for the GUI thread)."""
    s = LandmarkSession.load(rig, landmarks, recordings, progress=progress.sub(0.0, 0.85))
    shown = {}
    names = [s.rig.depth().name] + s.camera_names()
    for i, c in enumerate(names):
        progress(0.85 + 0.15 * i / len(names), f"preparing the images: {c}")
        try:
            shown[(s.recording_key, c)] = shown_rgb8(s, c)
        except PlantregError:  # no image of this camera here: said when it is chosen
            pass
    return s, shown


class LandmarkPage(QWidget):
    """The page. ``open(rig, landmarks, recordings)`` or ``set_session(session)``."""

    overlay_ready = Signal()
    fit_done = Signal()

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.session: LandmarkSession | None = None
        self._workers = Jobs(self, on_progress=lambda t, f, m: (self.progress.setValue(int(1000 * f)),
                                                                 self.hint.setText(m)),
                             on_cancelled=lambda t: self.hint.setText(f"{t} cancelled."),
                             on_end=lambda w: (self._sync_enabled(), self.progress.setValue(0)))
        self._fit_worker: Worker | None = None
        self._refine_worker: Worker | None = None
        self._overlay_worker: Worker | None = None
        self._load_worker: Worker | None = None
        self._shown: dict[tuple[str, str], np.ndarray] = {}  # (recording, camera) -> RGB8 as shown
        self._overlay_dirty = False
        self.overlay: OverlayImages | None = None
        self._flick = False
        self._build()

    # ------------------------------------------------------------------ layout
    def _build(self) -> None:
        top = QHBoxLayout()
        self.open_button = QPushButton("Open…")
        self.open_button.setToolTip("open a rig and a landmarks file")
        self.open_button.clicked.connect(self._ask_open)
        self.recording_combo = ElideLeftCombo()
        self.recording_combo.setMinimumContentsLength(11)  # cut at its start (ElideLeftCombo)
        self.recording_combo.currentTextChanged.connect(self._on_recording)
        self.camera_combo = QComboBox()
        self.camera_combo.currentTextChanged.connect(self._on_camera)
        self.free_combo = QComboBox()
        self.free_combo.addItems(list(FREE_PRESETS))
        self.free_combo.setToolTip("what the fit may change in the other cameras")
        self.depth_free = QCheckBox("depth camera k1 + principal")
        self.depth_free.setToolTip("also fit the depth camera's first radial term and principal point "
                                   "(the Azure Kinect's lens is strongly distorted)")
        self.snap_depth = QCheckBox("snap depth to the nearer surface")
        self.snap_depth.setChecked(True)
        self.snap_depth.setToolTip(
            "a landmark whose depth lies behind the surface beside it (a click just past a leaf's edge or "
            "through a notch reads the ground) is put onto that surface; unchecked: it is left out of the fit "
            "(fit-rig --no-snap-depth). The table's depth column says which landmarks this concerns.")
        self.snap_depth.toggled.connect(lambda on: self._do(lambda: self.session.set_snap_depth(on)))
        self.fit_button = QPushButton("Fit")
        self.fit_button.setToolTip("fit the rig to all landmarks of all recordings (F)")
        self.fit_button.clicked.connect(self.run_fit)
        self.refine_button = QPushButton("Refine")
        self.refine_button.setToolTip("refine the camera poses from the images (normalised information distance)")
        self.refine_button.clicked.connect(self.run_refine)
        self.cancel_button = QPushButton("Cancel")
        self.cancel_button.setEnabled(False)
        self.cancel_button.clicked.connect(self.cancel)
        self.progress = QProgressBar()
        self.progress.setRange(0, 1000)
        self.progress.setMaximumWidth(160)
        self.progress.setTextVisible(False)
        self.undo_button = QPushButton("Undo")
        self.undo_button.clicked.connect(lambda: self._do(self.session.undo))
        self.redo_button = QPushButton("Redo")
        self.redo_button.clicked.connect(lambda: self._do(self.session.redo))
        self.delete_button = QPushButton("Delete point")
        self.delete_button.clicked.connect(lambda: self._do(self.session.delete_point))
        self.save_rig_button = QPushButton("Save rig…")
        self.save_rig_button.clicked.connect(self._ask_save_rig)
        self.save_lm_button = QPushButton("Save landmarks")
        self.save_lm_button.clicked.connect(self._ask_save_landmarks)
        self.camera_combo.setMinimumContentsLength(12)
        self.progress.setVisible(False)
        for w in (self.open_button, QLabel("Recording"), self.recording_combo, QLabel("Camera"), self.camera_combo,
                  self.undo_button, self.redo_button, self.delete_button, self.save_lm_button, self.save_rig_button):
            top.addWidget(w)
        top.addStretch(1)
        second = QHBoxLayout()
        for w in (QLabel("Fit frees"), self.free_combo, self.depth_free, self.snap_depth, self.fit_button,
                  self.refine_button, self.cancel_button, self.progress):
            second.addWidget(w)
        second.addStretch(1)

        self.left = PointView("depth camera")
        self.right = PointView("camera")
        self.over = PointView("overlay")
        for v in (self.left, self.right, self.over):
            v.setFocusPolicy(Qt.FocusPolicy.ClickFocus)
        self.left.clicked.connect(self._left_clicked)
        self.right.clicked.connect(self._right_clicked)
        for v, where in ((self.left, "depth"), (self.right, None)):
            v.marker_pressed.connect(lambda i: self._do(self.session.select, i))
            v.drag_started.connect(lambda i, w=where: self._drag_start(i, w))
            v.dragged.connect(lambda i, u, vv, w=where: self._drag(i, w, u, vv, False))
            v.drag_finished.connect(lambda i, u, vv, w=where: self._drag(i, w, u, vv, True))
        self.left.hovered.connect(lambda r, c: self.over.set_cursor_pixel(r, c))
        self.over.hovered.connect(lambda r, c: self.left.set_cursor_pixel(r, c))
        # the registration workspace's colour bars (limits in the modality's unit) and read-out
        # (Layer.value_text) for the raw images shown: a technician clicking leaf corners on a
        # thermal image sees the temperature scale and the value under the cursor
        self.left_bar, self.right_bar = ColourBar(), ColourBar()
        for bar in (self.left_bar, self.right_bar):  # a hidden bar (colour image) keeps the views level
            sp = bar.sizePolicy()
            sp.setRetainSizeWhenHidden(True)
            bar.setSizePolicy(sp)
        self.shown_layers: dict[str, Layer] = {}  # "left" / "right" -> the shown image's values
        self.readout = QLabel("")
        self.readout.setTextInteractionFlags(Qt.TextInteractionFlag.TextSelectableByMouse)
        self.readout.setMinimumWidth(10)  # a long read-out is clipped, never widens the window
        self.left.hovered.connect(lambda r, c: self._hover("left", r, c))
        self.right.hovered.connect(lambda r, c: self._hover("right", r, c))
        self.over.hovered.connect(lambda r, c: self._hover("left", r, c))  # the overlay is in the left grid
        self.left_title, self.right_title = QLabel(), QLabel()
        self.over_title = QLabel("Registered by the current rig")
        mode = QHBoxLayout()
        self.mode_combo = QComboBox()
        self.mode_combo.addItems(["blend", "checkerboard", "flicker"])
        self.mode_combo.currentTextChanged.connect(self._compose)
        self.alpha = QSlider(Qt.Orientation.Horizontal)
        self.alpha.setRange(0, 100)
        self.alpha.setValue(50)
        self.alpha.valueChanged.connect(self._compose)
        self.overlay_label = QLabel("")
        mode.addWidget(self.over_title)
        mode.addWidget(self.mode_combo)
        mode.addWidget(self.alpha, 1)
        self._flick_timer = QTimer(self)
        self._flick_timer.setInterval(500)
        self._flick_timer.timeout.connect(self._flicker_tick)

        views = QSplitter(Qt.Orientation.Horizontal)
        for title, bar, view, extra in ((self.left_title, self.left_bar, self.left, None),
                                        (self.right_title, self.right_bar, self.right, None),
                                        (None, None, self.over, mode)):
            box = QWidget()
            bl = QVBoxLayout(box)
            bl.setContentsMargins(2, 2, 2, 2)
            if title is not None:
                bl.addWidget(title)
            if bar is not None:
                bl.addWidget(bar)
            if extra is not None:
                bl.addLayout(extra)
                bl.addWidget(self.overlay_label)
            bl.addWidget(view, 1)
            views.addWidget(box)
        views.setSizes([500, 500, 500])

        self.table = QTableWidget(0, len(TABLE_COLUMNS))
        self.table.setHorizontalHeaderLabels(list(TABLE_COLUMNS))
        self.table.horizontalHeaderItem(TABLE_COLUMNS.index("depth")).setToolTip(
            "the depth the fit uses: the surface under the click, snapped onto a nearer surface beside it, "
            "or left out (hover a cell for why)")
        self.table.setSelectionBehavior(QAbstractItemView.SelectionBehavior.SelectRows)
        self.table.setSelectionMode(QAbstractItemView.SelectionMode.SingleSelection)
        self.table.setEditTriggers(QAbstractItemView.EditTrigger.NoEditTriggers)
        self.table.verticalHeader().setVisible(False)
        self.table.horizontalHeader().setStretchLastSection(True)
        self.table.itemSelectionChanged.connect(self._table_selected)

        nudge = QGroupBox("Nudge the camera (keys)")
        nf = QFormLayout(nudge)
        self.rot_step = QDoubleSpinBox()
        self.rot_step.setRange(0.01, 10.0)
        self.rot_step.setValue(0.2)
        self.rot_step.setSuffix(" °")
        self.rot_step.setDecimals(2)
        self.trans_step = QDoubleSpinBox()
        self.trans_step.setRange(0.1, 100.0)
        self.trans_step.setValue(2.0)
        self.trans_step.setSuffix(" mm")
        nf.addRow("rotation step", self.rot_step)
        nf.addRow("translation step", self.trans_step)
        nf.addRow(QLabel("W/S tilt, A/D pan, Q/E roll\n←/→ ↑/↓ move across, PgUp/PgDn forward/back\n"
                         "Shift = 5× step; F fit, Del delete, Esc cancel click"))
        self.report_text = QPlainTextEdit()
        self.report_text.setReadOnly(True)
        self.report_text.setPlaceholderText("Fit report: residuals per camera, worst landmarks")
        f = self.report_text.font()
        f.setFamily("monospace")
        self.report_text.setFont(f)
        self.hint = QLabel()
        self.hint.setWordWrap(True)

        bottom = QSplitter(Qt.Orientation.Horizontal)
        bottom.addWidget(self.table)
        bottom.addWidget(nudge)
        bottom.addWidget(self.report_text)
        bottom.setSizes([420, 260, 700])
        main = QSplitter(Qt.Orientation.Vertical)
        main.addWidget(views)
        main.addWidget(bottom)
        main.setSizes([640, 260])
        lay = QVBoxLayout(self)
        lay.addLayout(top)
        lay.addLayout(second)
        lay.addWidget(self.hint)
        lay.addWidget(main, 1)
        lay.addWidget(self.readout)

        # nudge keys: an event filter on the views (which would otherwise scroll with the arrows)
        # and the page's keyPressEvent, so they work wherever the focus is on this page
        for v in (self.left, self.right, self.over):
            v.installEventFilter(self)
        for seq, fn in ((QKeySequence.StandardKey.Undo, lambda: self._do(self.session.undo)),
                        (QKeySequence.StandardKey.Redo, lambda: self._do(self.session.redo)),
                        (QKeySequence(Qt.Key.Key_Delete), lambda: self._do(self.session.delete_point)),
                        (QKeySequence(Qt.Key.Key_Escape), lambda: self._do(self.session.cancel_pending)),
                        (QKeySequence(Qt.Key.Key_F), self.run_fit)):
            sc = QShortcut(QKeySequence(seq), self)
            sc.setContext(Qt.ShortcutContext.WidgetWithChildrenShortcut)
            sc.activated.connect(fn)
        self._overlay_timer = QTimer(self)
        self._overlay_timer.setSingleShot(True)
        self._overlay_timer.setInterval(250)  # nudges in quick succession: register once
        self._overlay_timer.timeout.connect(self.update_overlay)
        self._sync_enabled()
        self.hint.setText("Open a rig and a landmarks file (plantreg-gui --landmarks FILE --rig RIG).")

    # ------------------------------------------------------------------ session
    def open(self, rig: str | Path, landmarks: str | Path | None = None,
             recordings: list[str | Path] | None = None) -> Worker:
        """Open files on a worker (reading the recordings is too slow for the GUI thread): the page
        says it is reading, Cancel stops it, a bad file becomes a "Cannot open" dialog naming it,
        and the session read replaces the shown one. Opening again while reading drops the
        earlier read (its result, error or cancellation no longer concern the page)."""
        old = self._load_worker
        if old is not None:
            for sig in (old.finished, old.failed, old.cancelled):
                sig.disconnect()
            old.cancel()
        w = Worker(read_session, rig, landmarks, list(recordings or []))
        self._load_worker = w
        w.done.connect(lambda: setattr(self, "_load_worker", None) if self._load_worker is w else None)
        self.hint.setText("Reading the rig, the landmarks and the recordings…")
        return self._start(w, lambda s: self._load_finished(w, s), "Opening", title="Cannot open")

    def _load_finished(self, w: Worker, result: tuple) -> None:
        if w is self._load_worker:  # not superseded, not shut down meanwhile
            self.set_session(*result)

    def set_session(self, s: LandmarkSession, shown: dict[tuple[str, str], np.ndarray] | None = None) -> None:
        """Show session ``s``; ``shown``: images already converted for showing (see :func:`read_session`)."""
        self.session = s
        self._shown = dict(shown or {})
        s.events.points.connect(self._points_changed)
        s.events.selection.connect(self._selection_changed)
        s.events.rig.connect(self._rig_changed)
        s.events.report.connect(self._report_changed)
        s.events.options.connect(self._options_changed)
        self._options_changed()
        self.recording_combo.blockSignals(True)
        self.recording_combo.clear()
        self.recording_combo.addItems(s.recording_keys)
        self.recording_combo.setCurrentText(s.recording_key or "")
        for i, k in enumerate(s.recording_keys):
            self.recording_combo.setItemData(i, k, Qt.ItemDataRole.ToolTipRole)
        self.recording_combo.setToolTip(s.recording_key or "")
        self.recording_combo.blockSignals(False)
        self.camera_combo.blockSignals(True)
        self.camera_combo.clear()
        self.camera_combo.addItems(s.camera_names())
        self.camera_combo.setCurrentText(s.camera or "")
        self.camera_combo.blockSignals(False)
        self._show_images()
        self._points_changed()
        self._selection_changed()
        self._report_changed()
        self.update_overlay()

    def _do(self, fn, *args) -> None:
        """Run a session action from a button or key; user mistakes become a dialog."""
        if self.session is None:
            return
        try:
            fn(*args)
        except PlantregError as e:
            show_error(self, "Landmarks", str(e))

    def _on_recording(self, key: str) -> None:
        self.recording_combo.setToolTip(key)
        if self.session is not None and key and key != self.session.recording_key:
            self._do(self.session.set_recording, key)
            self._show_images()
            self._points_changed()
            self.update_overlay()

    def _on_camera(self, cam: str) -> None:
        if self.session is not None and cam and cam != self.session.camera:
            self._do(self.session.set_camera, cam)
            self._show_images()
            self._points_changed()
            self.update_overlay()

    def _show_images(self) -> None:
        s = self.session
        dname = s.rig.depth().name
        try:
            self.left.set_rgb8(self._image_rgb8(dname))
            self.right.set_rgb8(self._image_rgb8(s.camera))
        except PlantregError as e:
            show_error(self, "Landmarks", str(e))
            return
        self.left_title.setText(f"<b>{dname}</b> (depth camera) — click a point here first")
        self.right_title.setText(f"<b>{s.camera}</b> — then the same point here")
        self._show_scales()
        self._home_on_points()

    def _image_rgb8(self, camera: str) -> np.ndarray:
        """``camera``'s image of the current recording as shown, converted once (going back to a
        camera is instant); only the current recording's are kept."""
        key = (self.session.recording_key, camera)
        if key not in self._shown:
            self._shown = {k: v for k, v in self._shown.items() if k[0] == key[0]}
            self._shown[key] = shown_rgb8(self.session, camera)
        return self._shown[key]

    def _home_on_points(self) -> None:
        """Zoom both views to the clicked points (with a margin): where the work is."""
        from PySide6.QtCore import QRectF

        s = self.session
        for view, uvs in ((self.left, [lm.depth_uv for lm in s.points]),
                          (self.right, [lm.cameras[s.camera] for lm in s.points if s.camera in lm.cameras])):
            if view.array is None:
                continue
            h, w = view.array.shape[:2]
            if len(uvs) < 2:
                view.set_home(None)
                continue
            a = np.asarray(uvs)
            lo, hi = a.min(0), a.max(0)
            m = np.maximum(0.25 * (hi - lo), 0.08 * max(h, w))
            lo, hi = np.maximum(lo - m, 0), np.minimum(hi + m, [w, h])
            view.set_home(QRectF(lo[0], lo[1], hi[0] - lo[0], hi[1] - lo[1]))

    def _show_scales(self) -> None:
        """The colour bars and read-out of the shown images, from their values (the workspace's
        raw layers: modality, unit, wavelengths; the depth map in mm when there is no image)."""
        s = self.session
        d = s.rig.depth()
        layers = {L.name: L for L in raw_layers(s.rig, s.recording())}
        left = layers.get(d.name) or layers.get(DEPTH)
        self.shown_layers = {k: L for k, L in (("left", left), ("right", layers.get(s.camera))) if L is not None}
        # the left image is drawn with the depth camera's colour map, the depth map too (_show_images)
        left_st = DisplaySettings(cmap=modality.default_cmap(d.modality))
        for k, bar, st in (("left", self.left_bar, left_st), ("right", self.right_bar, None)):
            L = self.shown_layers.get(k)
            bar.set_bar(*(colour_bar_of(L, st) if L is not None else (None, None, "")))
        self.readout.setText("Move the cursor over an image to read its values.")

    def _hover(self, side: str, row: int, col: int) -> None:
        """The value under the cursor in the image's unit (the last pixel stays when the cursor leaves)."""
        L = self.shown_layers.get(side)
        if row < 0 or L is None:
            return
        h, w = L.data.shape[:2]
        text = f"{L.name} ({w}x{h})  x={col} y={row}: {L.value_text(row, col, L.middle_band)}"
        self.readout.setText(text)
        self.readout.setToolTip(text)

    # ------------------------------------------------------------------ repaint on events
    def _markers(self) -> tuple[list[Marker], list[Marker]]:
        s = self.session
        res = s.residuals()
        left, right = [], []
        for i, lm in enumerate(s.points):
            r = res.get(i)
            chk = s.depth_check(i)
            label = f"{i}" + (f": {r:.1f} px" if r is not None else "") + DEPTH_MARK.get(chk.status, "")
            col = (255, 220, 0) if r is None or r < 3 else (255, 140, 0) if r < 8 else (255, 60, 60)
            if not chk.used:  # not in the fit: no residual to colour by
                col = (255, 60, 60)
            if s.camera not in lm.cameras:  # a point of another camera: grey, drawn underneath
                left.insert(0, Marker(i, lm.depth_uv, "", colour=(150, 150, 150)))  # no label: they pile up
                continue
            left.append(Marker(i, lm.depth_uv, label, colour=col))
            if s.camera in lm.cameras:
                pred = s.predicted(i) if r is not None else None
                right.append(Marker(i, lm.cameras[s.camera], label, pred, col))
        return left, right

    def _points_changed(self) -> None:
        s = self.session
        left, right = self._markers()
        self.left.set_markers(left, s.selected, s.pending)
        self.right.set_markers(right, s.selected)
        self.over.set_markers([Marker(m.index, m.uv, "", colour=m.colour) for m in left if m.label], s.selected)
        rows = s.table()
        self.table.blockSignals(True)
        self.table.setRowCount(len(rows))
        for r, d in enumerate(rows):
            vals = [str(d["index"]), "—" if d["residual_px"] is None else f"{d['residual_px']:.2f}",
                    depth_text(d["depth"]), f"{d['depth_uv'][0]:.1f}, {d['depth_uv'][1]:.1f}",
                    "—" if d["camera_uv"] is None else f"{d['camera_uv'][0]:.1f}, {d['camera_uv'][1]:.1f}", d["note"]]
            for c, v in enumerate(vals):
                it = QTableWidgetItem(v)
                it.setData(Qt.ItemDataRole.UserRole, d["index"])
                self.table.setItem(r, c, it)
            chk = d["depth"]
            cell = self.table.item(r, TABLE_COLUMNS.index("depth"))
            if chk.status != "ok":
                cell.setToolTip(chk.reason)
                cell.setBackground(QColor(*DEPTH_COLOURS[chk.status]))
                cell.setForeground(QColor(0, 0, 0))
            if d["index"] == s.selected:
                self.table.selectRow(r)
        self.table.resizeColumnsToContents()
        self.table.blockSignals(False)
        self._sync_enabled()

    def _options_changed(self) -> None:
        self.snap_depth.blockSignals(True)
        self.snap_depth.setChecked(self.session.snap_depth)
        self.snap_depth.blockSignals(False)

    def _selection_changed(self) -> None:
        s = self.session
        self.right.grab_markers = s.pending is None
        self.left.set_markers(self.left.markers, s.selected, s.pending)
        self.right.set_markers(self.right.markers, s.selected)
        self.over.set_markers(self.over.markers, s.selected)
        n = len(s.points)
        if s.pending is not None:
            self.hint.setText(f"Now click the same point in <b>{s.camera}</b> (Esc cancels).")
        elif s.selected is not None:
            chk = s.depth_check(s.selected)
            depth = "" if chk.status == "ok" else (
                f" Depth check: {html.escape(chk.reason, quote=False)}"
                + (f"; snapped to {chk.z_m:.3f} m." if chk.status == "snapped" else "."))
            self.hint.setText(f"Point {s.selected} selected: drag it to move, Del to delete. "
                              f"{n} points in this recording.{depth}")
            self._show_selected_row()
        else:
            self.hint.setText(f"{n} points in this recording, {s.landmarks.count()} in all. Click a point in "
                              f"the depth camera, then in {s.camera}. Wheel zooms, drag pans, double-click fits.")
        self._sync_enabled()

    def _show_selected_row(self) -> None:
        t, sel = self.table, self.session.selected
        for r in range(t.rowCount()):
            if t.item(r, 0) is not None and int(t.item(r, 0).data(Qt.ItemDataRole.UserRole)) == sel:
                if r not in {i.row() for i in t.selectedItems()}:
                    t.blockSignals(True)
                    t.selectRow(r)
                    t.blockSignals(False)
                t.scrollToItem(t.item(r, 0))
                return

    def _rig_changed(self) -> None:
        self._overlay_timer.start()

    def _report_changed(self) -> None:
        s = self.session
        rep = s.report or {}
        text = []
        if not rep or not s.report_is_current:
            # the report below (if any) is of another rig: lead with the current rig's residuals
            text.append(self._rig_heading() if not rep else
                        "Residuals of the current rig (moved by hand since the report below):")
            for c, v in s.summary().items():
                text.append(f"  {c:<16} n={v['n']:<4} median {v['median_px']:.2f} px   p90 {v['p90_px']:.2f} px   "
                            f"max {v['max_px']:.2f} px"
                            + (f"   ({v['set_aside']} set aside by the fit as outliers)" if v.get("set_aside") else ""))
            if rep:
                text.append("\nBefore the nudges:")
        if "per_camera" in rep:
            from ...core.rigfit.rigfit import format_report

            text.append(format_report(rep))
        if "refine" in rep or "cameras" in rep:
            cams = rep.get("refine", rep).get("cameras", {})
            for c, v in cams.items():
                text.append(f"refine {c}: cost {v.get('start_cost', float('nan')):.3f} -> "
                            f"{v.get('end_cost', float('nan')):.3f}, "
                            f"{'converged' if v.get('converged') else 'NOT converged'}")
        text += [f"warning: {w}" for w in s.warnings]
        self.report_text.setPlainText("\n".join(text))

    def _rig_heading(self) -> str:
        """What the rig without a fit on this page is: as opened (fitted before or not), or moved."""
        s = self.session
        if "rig" in s.unsaved():
            return "Residuals of the current rig (moved by hand, not fitted here):"
        cal = s.rig.extra.get("calibration")
        if isinstance(cal, dict):  # e.g. the shipped rig, fitted by plantreg fit-rig
            when = f", {str(cal['date'])[:10]}" if cal.get("date") else ""
            return f"Residuals of the rig as opened (fitted before: {cal.get('method', 'unknown method')}{when}):"
        return "Residuals of the rig as opened (not fitted yet):"

    def _sync_enabled(self) -> None:
        s = self.session
        busy = self.is_busy(include_overlay=False)
        for b in (self.fit_button, self.refine_button, self.save_rig_button, self.save_lm_button,
                  self.recording_combo, self.camera_combo, self.snap_depth):
            b.setEnabled(s is not None and not busy)
        self.undo_button.setEnabled(s is not None and not busy and s.can_undo())
        self.redo_button.setEnabled(s is not None and not busy and s.can_redo())
        self.delete_button.setEnabled(s is not None and not busy and s.selected is not None)
        self.cancel_button.setEnabled(busy)
        self.progress.setVisible(busy)

    # ------------------------------------------------------------------ clicks and drags
    def _left_clicked(self, u: float, v: float) -> None:
        self._do(self.session.click_depth, (u, v))

    def _right_clicked(self, u: float, v: float) -> None:
        s = self.session
        if s.pending is None and (s.selected is None or s.camera in s.points[s.selected].cameras):
            self.hint.setText(f"Click the point in <b>{s.rig.depth().name}</b> first (left view).")
            return
        self._do(s.click_camera, (u, v))

    def _drag_start(self, i: int, where: str | None) -> None:
        s = self.session
        w = where or s.camera
        cur = s.points[i].depth_uv if w == "depth" else s.points[i].cameras[w]
        s.move_point(i, w, cur, undoable=True)  # one undo step for the whole drag

    def _drag(self, i: int, where: str | None, u: float, v: float, final: bool) -> None:
        self.session.move_point(i, where or self.session.camera, (u, v), undoable=False)

    def _table_selected(self) -> None:
        items = self.table.selectedItems()
        if items and self.session is not None:
            self.session.select(int(items[0].data(Qt.ItemDataRole.UserRole)))

    # ------------------------------------------------------------------ nudge
    def eventFilter(self, obj, e) -> bool:  # noqa: N802
        from PySide6.QtCore import QEvent

        if e.type() == QEvent.Type.KeyPress and e.key() in NUDGE_KEYS:
            self.nudge_key(e.key(), bool(e.modifiers() & Qt.KeyboardModifier.ShiftModifier))
            return True
        return super().eventFilter(obj, e)

    def keyPressEvent(self, e) -> None:  # noqa: N802
        if e.key() in NUDGE_KEYS:
            self.nudge_key(e.key(), bool(e.modifiers() & Qt.KeyboardModifier.ShiftModifier))
        else:
            super().keyPressEvent(e)

    def nudge_key(self, key, fast: bool = False) -> None:
        if self.session is None or self.is_busy(include_overlay=False):
            return
        kind, axis, sign = NUDGE_KEYS[Qt.Key(key)]
        step = self.rot_step.value() if kind == "rotate" else self.trans_step.value() / 1000.0
        self._do(self.session.nudge, kind, axis, sign * step * (5.0 if fast else 1.0))

    # ------------------------------------------------------------------ workers
    def free_items(self) -> frozenset[str]:
        s = self.session
        items = {f"{c}:{it}" for c in s.landmarks.camera_names for it in FREE_PRESETS[self.free_combo.currentText()]}
        if self.depth_free.isChecked():
            d = s.rig.depth().name
            items |= {f"{d}:k1", f"{d}:principal"}
        return frozenset(items)

    def _start(self, w: Worker, on_done, label: str, title: str | None = None) -> Worker:
        self._workers.start(w, label, on_done, error_title=title or label)
        self._sync_enabled()
        return w

    def run_fit(self) -> None:
        if self.session is None or self.is_busy(include_overlay=False):
            return
        self.session.free = self.free_items()
        self.hint.setText("Fitting…")
        self._fit_worker = self._start(Worker(self.session.fit_job()), self._fit_finished, "Fit")

    def _fit_finished(self, result) -> None:
        self.session.apply_fit(result)
        pc = result.report.get("per_camera", {})
        self.hint.setText("Fitted: " + ", ".join(f"{c} median {v['median_px']:.2f} px (n={v['n']})"
                                                 for c, v in pc.items()))
        self.fit_done.emit()

    def run_refine(self) -> None:
        if self.session is None or self.is_busy(include_overlay=False):
            return
        self.session.free = self.free_items()
        try:
            job = self.session.refine_job(in_process=True)  # stopped at once by Cancel, no GIL held here
        except PlantregError as e:
            show_error(self, "Refine", str(e))
            return
        self.hint.setText("Refining from the images…")
        self._refine_worker = self._start(Worker(job), self._refine_finished, "Refine")

    def _refine_finished(self, result) -> None:
        s = self.session
        rep = dict(s.report or {})
        rep["refine"] = result.report
        result.report = rep
        s.apply_fit(result)
        self.hint.setText("Refined. " + " ".join(result.warnings[:2]))
        self.fit_done.emit()

    def cancel(self) -> None:
        for w in list(self._workers):
            if w is not self._overlay_worker:
                w.cancel()

    def update_overlay(self) -> None:
        """Register the chosen camera into the infrared with the current rig, on a worker."""
        if self.session is None:
            return
        if self._overlay_worker is not None and self._overlay_worker.is_running():
            self._overlay_dirty = True  # run again with the newest rig when this one ends
            return
        self._overlay_dirty = False
        self.overlay_label.setText("registering…")
        try:
            job = self.session.overlay_job()
        except PlantregError as e:
            self.overlay_label.setText(str(e))
            return
        w = Worker(job)
        self._overlay_worker = w
        self._workers.start(w, "Overlay", self._overlay_finished, background=True,
                            on_failed=lambda msg, det: self.overlay_label.setText(f"overlay failed: {msg}"),
                            on_end=lambda w: self._overlay_again())

    def _overlay_again(self) -> None:
        if self._overlay_dirty:
            self.update_overlay()
        else:
            self.overlay_ready.emit()

    def _overlay_finished(self, ov: OverlayImages) -> None:
        self.overlay = ov
        self.overlay_label.setText(f"{ov.camera} on {self.session.rig.depth().name}: "
                                   f"seen in {100 * ov.mapped.mean():.0f} % of the image")
        self._compose()

    def _compose(self, *_a) -> None:
        ov = self.overlay
        if ov is None:
            return
        mode = self.mode_combo.currentText()
        self.alpha.setVisible(mode == "blend")
        if mode == "flicker":
            self._flick_timer.start()
            img = ov.registered if self._flick else ov.base
        else:
            self._flick_timer.stop()
            if mode == "blend":
                img = blend(ov.base, ov.registered, self.alpha.value() / 100.0)
            else:
                img = checkerboard(ov.base, ov.registered, default_tile(ov.base.shape))
            img = np.where(ov.mapped[..., None], img, ov.base)  # unmapped pixels: the infrared alone
        self.over.set_rgb8(np.ascontiguousarray(img))

    def _flicker_tick(self) -> None:
        self._flick = not self._flick
        self._compose()

    # ------------------------------------------------------------------ saving
    def confirm_discard(self, action: str) -> bool:
        """True when nothing unsaved would be lost by ``action`` (e.g. "Close") or the user agrees
        to discard it; False (keep working) otherwise."""
        from PySide6.QtWidgets import QMessageBox

        what = self.session.unsaved() if self.session is not None else []
        if not what:
            return True
        names = {"landmarks": "the landmarks", "rig": "the fitted or nudged rig"}
        text = (f"{' and '.join(names[w] for w in what).capitalize()} "
                f"{'are' if len(what) > 1 else 'is'} not saved. {action} anyway and lose "
                f"{'them' if len(what) > 1 else 'it'}?")
        B = QMessageBox.StandardButton
        return QMessageBox.warning(self, f"{action}: unsaved work", text, B.Discard | B.Cancel, B.Cancel) == B.Discard

    def _ask_open(self) -> None:
        if not self.confirm_discard("Open another rig"):
            return
        rig, _ = QFileDialog.getOpenFileName(self, "Rig file", "", "Rig (*.json)")
        if not rig:
            return
        lm, _ = QFileDialog.getOpenFileName(self, "Landmarks file", str(Path(rig).parent), "Landmarks (*.json)")
        if lm:
            try:
                self.open(rig, lm)
            except PlantregError as e:
                show_error(self, "Cannot open", str(e))

    def _ask_save_rig(self) -> None:
        if self.session is None:
            return
        path, _ = QFileDialog.getSaveFileName(self, "Save rig", "rig.json", "Rig (*.json)")
        if path:
            self._do(self.session.save_rig, path)

    def _ask_save_landmarks(self) -> None:
        s = self.session
        if s is None:
            return
        path = s.landmarks.path
        if path is None:
            p, _ = QFileDialog.getSaveFileName(self, "Save landmarks", "landmarks.json", "Landmarks (*.json)")
            if not p:
                return
            path = Path(p)
        self._do(s.save_landmarks, path)
        self.hint.setText(f"Landmarks saved to {path}.")

    # ------------------------------------------------------------------ app hooks
    def is_busy(self, include_overlay: bool = True) -> bool:
        return any(w.is_running() for w in self._workers
                   if include_overlay or w is not self._overlay_worker)

    def shutdown(self) -> None:
        self._load_worker = None  # a session read after this is not shown
        self._flick_timer.stop()
        self._overlay_timer.stop()
        for w in list(self._workers):
            w.wait()
