"""The registration workspace: open a rig and a recording, register on a worker, inspect the
result side by side, as a mosaic, with case/area overlays and as a 3D point cloud, export.

All computation happens in the core (:mod:`plantreg_gui.core.register`, ``display``, ``export``)
and in the Qt-free :mod:`.model`; long work runs on :class:`~plantreg_gui.gui.workers.Worker`
threads which hand numpy arrays back to slots on the GUI thread.
"""

from __future__ import annotations

import shutil
import tempfile
from pathlib import Path
from typing import Any, Callable

import numpy as np
from PySide6.QtCore import QEvent, QRectF, QSettings, Qt, Signal
from PySide6.QtWidgets import (
    QComboBox, QFileDialog, QInputDialog, QLabel, QMenu, QMessageBox, QProgressBar, QPushButton, QSplitter,
    QStatusBar, QTabWidget, QToolBar, QToolButton, QVBoxLayout, QWidget,
)

from ...core.display import canonical_modality
from ...core.errors import InputError, PlantregError
from ...core.recording import MANIFEST, Recording
from ...core.rig import Rig
from ..workers import Worker, show_error
from . import plant3d
from .cloud_view import CloudView
from .display_controls import DisplayControls
from .export_dialog import ExportDialog, folder_is_nonempty
from .image_views import SpectrumPlot, ViewGrid
from .masks_view import MasksView
from .model import DEPTH, Cloud, DisplaySettings, Layer, build_cloud, raw_layers, registered_layers, render
from .mosaic_view import MosaicView

VIEWS = {"raw": "Raw images", "side-by-side": "Side by side", "mosaic": "Mosaic", "masks": "Masks", "3d": "3D"}
RECENT_KEY = "workspace/recent"
MAX_RECENT = 10


# ---------------------------------------------------------------------- worker jobs (no Qt)
def _render_layers(layers: list[Layer], settings: dict[str, DisplaySettings], progress) -> dict[str, np.ndarray]:
    out = {}
    for i, L in enumerate(layers):
        progress(i / max(len(layers), 1), f"rendering {L.name}")
        out[L.name] = render(L.data, L.modality, settings.get(L.name))
    return out


def _load_job(rig_path: Path | None, rec_path: Path, rig: Rig | None, settings, progress) -> dict:
    if rig is None and rig_path is not None:
        rig = Rig.load(rig_path)
    progress(0.05, "reading the recording")
    rec = Recording.load(rec_path, rig)
    if rig is not None:
        rec.check(rig)
    layers = raw_layers(rig, rec)
    renders = _render_layers(layers, settings, progress.sub(0.6, 1.0))
    return {"rig": rig, "rig_path": rig_path, "recording": rec, "recording_path": rec_path,
            "layers": layers, "renders": renders}


def _demo_job(folder: Path, settings, progress) -> dict:
    from ...core.synthetic import write_demo

    progress(0.0, "writing the demo rig and recording")
    # the calibration session is the wizard's business; leaving it out halves the start-up
    write_demo(folder, calibration=False, progress=progress.sub(0.0, 0.6))
    return _load_job(folder / "rig.json", folder / "recording", None, settings, progress.sub(0.6, 1.0))


def _meshes_of(registrar: Any) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """(vertices (V, 3), triangles (T, 3)) of the registrar's object and uncertainty meshes, as far
    as it exposes them (legacy or tensor Open3D meshes, or (V, T) tuples)."""
    out = {}
    holder = getattr(registrar, "meshes", None) or registrar  # core.register.Meshes
    for label, names in (("object mesh", ("object", "object_mesh")),
                         ("uncertainty mesh", ("uncertainty", "uncertainty_mesh"))):
        for n in names:
            m = getattr(holder, n, None)
            vt = _as_vt(m)
            if vt is not None:
                out[label] = vt
                break
    return out


def _as_vt(m: Any) -> tuple[np.ndarray, np.ndarray] | None:
    if m is None:
        return None
    try:
        if isinstance(m, tuple) and len(m) == 2:
            v, t = m
        elif hasattr(m, "vertex") and hasattr(m, "triangle"):  # open3d.t.geometry.TriangleMesh
            v, t = m.vertex.positions.numpy(), m.triangle.indices.numpy()
        elif hasattr(m, "vertices") and hasattr(m, "triangles"):
            v, t = np.asarray(m.vertices), np.asarray(m.triangles)
        elif hasattr(m, "vertices") and hasattr(m, "faces"):
            v, t = np.asarray(m.vertices), np.asarray(m.faces)
        else:
            return None
        v = np.asarray(v, dtype=np.float32).reshape(-1, 3)
        t = np.asarray(t, dtype=np.int64).reshape(-1, 3)
        return (v, t) if len(t) else None
    except (AttributeError, ValueError, TypeError):
        return None


def _register_job(registrar, rig: Rig, rec: Recording, target: str, settings, progress) -> dict:
    from ...core.register import Registrar

    if registrar is None:
        registrar = Registrar(rig, rec)
    result = registrar.register(target, progress.sub(0.0, 0.85))
    layers = registered_layers(result, rig)
    renders = _render_layers(layers, settings, progress.sub(0.85, 0.97))
    progress(0.97, "building the point cloud")
    cloud = build_cloud(result.points_rig, layers, renders)
    meshes = _meshes_of(registrar)
    progress(1.0, "done")
    return {"registrar": registrar, "result": result, "layers": layers, "renders": renders,
            "cloud": cloud, "meshes": meshes}


def _plant3d_job(folder: Path, plant: str, settings, progress) -> dict:
    p = plant3d.load_plant(folder, plant, progress.sub(0.0, 0.5))
    layers = []
    for name, img in p.images.items():
        data = img
        if name == "depth":
            data = img.astype(np.float32)
            data[~(data > 0)] = np.nan
        layers.append(Layer(name, p.modalities[name], data, None, p.units[name]))
    renders = _render_layers(layers, settings, progress.sub(0.5, 0.9))
    cloud = Cloud(p.points, p.point_pixels)
    for L in layers:
        if L.data.shape[:2] == p.depth_shape:
            cloud.colours[L.name] = renders[L.name].reshape(-1, 3)[p.point_pixels]
            cloud.values[L.name] = L.data.reshape(-1)[p.point_pixels].astype(np.float32)
            cloud.modalities[L.name] = L.modality
    return {"plant": p, "layers": layers, "renders": renders, "cloud": cloud}


# ---------------------------------------------------------------------- empty views
class _EmptyNote(QLabel):
    """A centred note laid over a view while it has nothing to show, saying why and what to do
    (an empty grey pane would look like a fault)."""

    def __init__(self, host: QWidget):
        super().__init__(host)
        self.setObjectName("emptyNote")
        self.setWordWrap(True)
        self.setAlignment(Qt.AlignmentFlag.AlignCenter)
        self.setStyleSheet("QLabel#emptyNote { color: #555; font-size: 12pt; padding: 40px;"
                           " background: #f4f4f4; }")
        self.setTextInteractionFlags(Qt.TextInteractionFlag.NoTextInteraction)
        host.installEventFilter(self)
        self.setGeometry(host.rect())
        self.hide()

    def eventFilter(self, obj, event) -> bool:  # noqa: N802 (Qt name)
        if obj is self.parent() and event.type() == QEvent.Type.Resize:
            self.setGeometry(obj.rect())
        return False

    def show_text(self, text: str) -> None:
        self.setText(text)
        self.setVisible(bool(text))
        if text:
            self.raise_()


# ---------------------------------------------------------------------- the widget
class RegistrationWorkspace(QWidget):
    """See the module docstring. Signals: ``registered(result)`` after each registration,
    ``exported(path)`` after an export, ``idle()`` when the last worker ends."""

    idle = Signal()
    registered = Signal(object)
    exported = Signal(object)

    def __init__(self, parent: QWidget | None = None):
        super().__init__(parent)
        self.setAcceptDrops(True)
        self.rig: Rig | None = None
        self.rig_path: Path | None = None
        self.recording: Recording | None = None
        self.recording_path: Path | None = None
        self.registrar = None
        self.result = None
        self.plant: plant3d.Plant3DRecording | None = None
        self.layers: list[Layer] = []            # registered (target grid)
        self.renders: dict[str, np.ndarray] = {}
        self.raw: list[Layer] = []
        self.raw_renders: dict[str, np.ndarray] = {}
        self.cloud: Cloud | None = None
        self.last_export: Path | None = None
        self.readout_text = ""
        self._workers: list[Worker] = []
        self._pending_target: str | None = None
        self._view_chosen = False
        self._generation = 0
        self._demo_tmp: tempfile.TemporaryDirectory | None = None
        self._build_ui()

    # ------------------------------------------------------------------ UI
    def _build_ui(self) -> None:
        tb = QToolBar("Workspace")
        tb.setToolButtonStyle(Qt.ToolButtonStyle.ToolButtonTextOnly)
        self.file_menu = QMenu("File", self)
        self.file_menu.addAction("Open rig…", lambda: self._guard(self._ask_rig))
        self.file_menu.addAction("Open recording…", lambda: self._guard(self._ask_recording))
        self.file_menu.addAction("Open Plant3DImageReg recording…", lambda: self._guard(self._ask_plant3d))
        self.recent_menu = self.file_menu.addMenu("Open recent")
        self.recent_menu.aboutToShow.connect(self._fill_recent)
        self.file_menu.addAction("Fit rig from landmarks…", lambda: self.window().show_landmarks(self.rig_path, getattr(self.recording, "folder", None)))  # noqa: E501
        self.file_menu.addSeparator()
        self.file_menu.addAction("Load demo", lambda: self._guard(self.load_demo))
        self.export_action = self.file_menu.addAction("Export…", self._ask_export)
        self.export_action.setEnabled(False)
        fb = QToolButton()
        fb.setText("File")
        fb.setMenu(self.file_menu)
        fb.setPopupMode(QToolButton.ToolButtonPopupMode.InstantPopup)
        tb.addWidget(fb)
        tb.addAction("Open rig…", lambda: self._guard(self._ask_rig))
        tb.addAction("Open recording…", lambda: self._guard(self._ask_recording))
        tb.addSeparator()
        tb.addWidget(QLabel(" Target camera "))
        self.target_combo = QComboBox()
        self.target_combo.setMinimumWidth(110)
        self.target_combo.setToolTip("register every camera into this camera's view")
        tb.addWidget(self.target_combo)
        self.register_button = QPushButton("Register")
        self.register_button.setEnabled(False)
        self.register_button.clicked.connect(lambda: self.run_registration(self.target_combo.currentText()))
        tb.addWidget(self.register_button)
        tb.addSeparator()
        self.export_button = QPushButton("Export…")
        self.export_button.setEnabled(False)
        self.export_button.clicked.connect(self._ask_export)
        tb.addWidget(self.export_button)
        tb.addSeparator()
        self.source_label = QLabel("Open a rig and a recording, drop a folder here, or File ▸ Load demo.")
        self.source_label.setStyleSheet("color: #444; padding-left: 6px;")
        tb.addWidget(self.source_label)

        self.banner = QLabel("")
        self.banner.setWordWrap(True)
        self.banner.setStyleSheet("background: #fff3c4; color: #5a4500; border: 1px solid #e0c060; padding: 6px;")
        self.banner.hide()

        self.tabs = QTabWidget()
        self.raw_grid = ViewGrid(linked=False)
        self.sbs_grid = ViewGrid(linked=True)
        self.mosaic_view = MosaicView()
        self.masks_view = MasksView()
        self.cloud_view = CloudView()
        self.views = {"raw": self.raw_grid, "side-by-side": self.sbs_grid, "mosaic": self.mosaic_view,
                      "masks": self.masks_view, "3d": self.cloud_view}
        for key, w in self.views.items():
            self.tabs.addTab(w, VIEWS[key])
        self.tabs.tabBarClicked.connect(lambda _i: setattr(self, "_view_chosen", True))
        self.empty_notes = {key: _EmptyNote(w) for key, w in self.views.items()}
        self.tabs.currentChanged.connect(self._tab_changed)
        self.raw_grid.hovered.connect(self._hover_raw)
        self.sbs_grid.hovered.connect(self._hover_target)
        self.mosaic_view.hovered.connect(self._hover_target)
        self.masks_view.hovered.connect(self._hover_target)

        self.controls = DisplayControls()
        self.controls.changed.connect(self._display_changed)
        self.spectrum = SpectrumPlot()
        self.summary = QLabel("")
        self.summary.setWordWrap(True)
        self.summary.setAlignment(Qt.AlignmentFlag.AlignTop | Qt.AlignmentFlag.AlignLeft)
        self.summary.setStyleSheet("font-size: 11px;")
        side = QWidget()
        sl = QVBoxLayout(side)
        sl.setContentsMargins(4, 0, 0, 0)
        sl.addWidget(self.controls)
        self.spectrum_label = QLabel("Spectrum under the cursor")
        sl.addWidget(self.spectrum_label)
        sl.addWidget(self.spectrum)
        sl.addWidget(self.summary, 1)
        self.spectrum.hide()  # shown once a multi-band image is open (an empty plot says nothing)
        self.spectrum_label.hide()
        side.setMinimumWidth(290)
        side.setMaximumWidth(360)

        split = QSplitter(Qt.Orientation.Horizontal)
        split.addWidget(self.tabs)
        split.addWidget(side)
        split.setStretchFactor(0, 1)
        split.setStretchFactor(1, 0)
        split.setChildrenCollapsible(False)

        self.status = QStatusBar()
        self.status.setSizeGripEnabled(False)
        self.readout = QLabel("")
        self.readout.setTextInteractionFlags(Qt.TextInteractionFlag.TextSelectableByMouse)
        self.status.addWidget(self.readout, 1)
        self.progress = QProgressBar()
        self.progress.setRange(0, 1000)
        self.progress.setMinimumWidth(360)
        self.progress.setTextVisible(True)
        self.progress.hide()
        self.cancel_button = QPushButton("Cancel")
        self.cancel_button.clicked.connect(self.cancel)
        self.cancel_button.hide()
        self.status.addPermanentWidget(self.progress)
        self.status.addPermanentWidget(self.cancel_button)

        lay = QVBoxLayout(self)
        lay.setContentsMargins(4, 2, 4, 0)
        lay.setSpacing(3)
        lay.addWidget(tb)
        lay.addWidget(self.banner)
        lay.addWidget(split, 1)
        lay.addWidget(self.status)
        self._update_empty_notes()

    def _update_empty_notes(self) -> None:
        """Say in every empty view why it is empty and what fills it."""
        busy = {getattr(w, "_kind", "") for w in self._workers}
        registering = "register" in busy or (self._pending_target is not None and bool(busy))
        loading = [w for w in self._workers if getattr(w, "_kind", "") == "load"]
        if loading and not self.raw:
            raw = f"{getattr(loading[0], '_title', 'Reading the recording')}… the images appear here when read."
        elif self.raw:
            raw = ""
        elif self.rig is not None:
            raw = ("Rig open. Now open the recording that goes with it (Open recording…, or drop its "
                   "folder here): its raw images are shown in Raw images at once.")
        else:
            raw = "Open a rig and a recording (File menu, or drop a folder here), or File ▸ Load demo."
        if self.result is not None:
            reg = ""
        elif registering:
            target = self._pending_target or self.target_combo.currentText()
            reg = f"Registering into {target}… this view fills in when it is done."
        elif self.plant is not None:
            reg = ("Nothing registered: no calibration ships with this data set, and registration needs a rig "
                   "file with the cameras' intrinsics and extrinsics.\nThe raw images are in Raw images, "
                   "the depth camera's point cloud in 3D.")
        elif self.rig is not None and self.recording is not None:
            reg = "Not registered yet: choose the target camera in the toolbar and press Register."
        else:
            reg = raw or "Open a rig and a recording, then press Register."
        cloud = "" if self.cloud is not None else reg
        for key, note in self.empty_notes.items():
            note.show_text(raw if key == "raw" else cloud if key == "3d" else reg)

    # ------------------------------------------------------------------ contract for main_window
    def is_busy(self) -> bool:
        return bool(self._workers) or self._pending_target is not None

    def set_view(self, name: str) -> None:
        key = name.strip().lower().replace("_", "-")
        key = {"sidebyside": "side-by-side", "side": "side-by-side", "3-d": "3d", "cloud": "3d",
               "mask": "masks"}.get(key, key)
        if key not in VIEWS:
            raise InputError(f"unknown view '{name}'; choose from {', '.join(VIEWS)}")
        self._view_chosen = True
        self.tabs.setCurrentWidget(self.views[key])

    def current_view(self) -> str:
        w = self.tabs.currentWidget()
        return next(k for k, v in self.views.items() if v is w)

    def prepare_screenshot(self) -> None:
        if self.current_view() == "3d":
            self.cloud_view.render_now()

    def shutdown(self) -> None:
        self._pending_target = None
        for w in list(self._workers):
            w.cancel()
        for w in list(self._workers):
            w.wait(30000)
        self.mosaic_view.stop()
        self.cloud_view.close_plotter()
        if self._demo_tmp is not None:
            self._demo_tmp.cleanup()
            self._demo_tmp = None

    # ------------------------------------------------------------------ opening
    def load_demo(self, target: str | None = None) -> None:
        """Write the synthetic demo to a temporary folder (on a worker), open it and register it."""
        if self._demo_tmp is None:
            self._demo_tmp = tempfile.TemporaryDirectory(prefix="plantreg-demo-")
        folder = Path(self._demo_tmp.name) / "demo"
        if folder.exists():
            shutil.rmtree(folder)
        self._pending_target = target or "ir"
        self._start(Worker(_demo_job, folder, dict(self.controls.settings)), "Preparing the demo",
                    self._loaded)

    def open_rig(self, path: str | Path) -> None:
        """Read a rig file (raises :class:`InputError` naming the file if it is bad)."""
        path = Path(path)
        rig = Rig.load(path)
        if self.recording is not None:
            self.recording.check(rig)  # raises before anything changes
        self.rig, self.rig_path = rig, path
        self._forget_registration()
        self._fill_targets()
        self._add_recent("rig", str(path))
        if self.recording is not None:
            self.raw = raw_layers(rig, self.recording)
            self.raw_renders = {L.name: render(L.data, L.modality, self.controls.settings_for(L.name))
                                for L in self.raw}
            self._show_raw()
        self._update_labels()
        self._update_empty_notes()

    def open_recording(self, path: str | Path) -> None:
        """Read a recording folder on a worker and show its raw images. Without an open rig, a
        ``rig.json`` beside or above the folder is opened with it. The Plant3DImageReg data set
        folder (asks for the plant) or ``DATASET/<plant>`` opens that data set's plant."""
        path = Path(path)
        if plant3d.is_dataset(path):  # the Plant3DImageReg data set: choose a plant
            self._ask_plant3d(path)
            return
        if not (path / MANIFEST).is_file() and plant3d.is_dataset(path.parent):  # DATASET/<plant>
            self.open_plant3d(path.parent, path.name)
            return
        rig_path = None
        if self.rig is None:
            for cand in (path / "rig.json", path.parent / "rig.json"):
                if cand.is_file():
                    rig_path = cand
                    break
        self._start(Worker(_load_job, rig_path, path, self.rig, dict(self.controls.settings)),
                    "Reading the recording", self._loaded)

    def open_plant3d(self, folder: str | Path, plant: str) -> None:
        """Open one plant of the Plant3DImageReg data set (raw images + nominal depth cloud)."""
        folder = Path(folder)
        if plant not in plant3d.list_plants(folder):
            raise InputError(f"no plant '{plant}' in the data set", folder)
        self._start(Worker(_plant3d_job, folder, plant, dict(self.controls.settings)),
                    f"Reading {plant}", self._plant_loaded)

    def _loaded(self, out: dict) -> None:
        self.plant = None
        self.banner.hide()
        if out["rig"] is not None and out["rig"] is not self.rig:
            self.rig, self.rig_path = out["rig"], out["rig_path"]
            self._add_recent("rig", str(out["rig_path"]))
        self.recording, self.recording_path = out["recording"], out["recording_path"]
        self._add_recent("recording", str(out["recording_path"]))
        self._forget_registration()
        self.raw, self.raw_renders = out["layers"], out["renders"]
        self._fill_targets()
        self._show_raw()
        self._update_labels()
        if self.rig is None:
            self.banner.setText("No rig is open: the raw images are shown; open the rig file (File ▸ Open rig…) "
                                "to register them.")
            self.banner.show()
        self._update_empty_notes()

    def _plant_loaded(self, out: dict) -> None:
        p = out["plant"]
        self.rig = self.rig_path = self.recording = self.recording_path = None
        self._forget_registration()
        self.plant = p
        self.raw, self.raw_renders = out["layers"], out["renders"]
        self._fill_targets()
        self._show_raw()
        self.cloud = out["cloud"]
        self.cloud_view.set_cloud(self.cloud, None, default="depth",
                                  note=f"{p.plant}: depth camera frame, nominal intrinsics (not calibrated).")
        missing = f" Not in the data set: {', '.join(p.missing)}." if p.missing else ""
        self.banner.setText(p.note + missing)
        self.banner.show()
        self.source_label.setText(f"Plant3DImageReg: {p.plant}  ({p.folder})")
        self._add_recent("plant3d", f"{p.folder}|{p.plant}")
        self._pending_target = None
        if not self._view_chosen:
            self.tabs.setCurrentWidget(self.raw_grid)
        self._update_empty_notes()

    def _forget_registration(self) -> None:
        self._generation += 1  # results of registrations still running belong to the old data
        self.registrar = None
        self.result = None
        self.layers, self.renders = [], {}
        self.cloud = None
        self.sbs_grid.set_layers([], {})
        self.mosaic_view.set_renders({}, [])
        self.cloud_view.set_cloud(None)
        self.export_action.setEnabled(False)
        self.export_button.setEnabled(False)
        self.summary.setText("")
        self.controls.set_layers(self.raw)
        self._update_empty_notes()

    def _fill_targets(self) -> None:
        keep = self.target_combo.currentText()
        self.target_combo.clear()
        if self.rig is not None:
            self.target_combo.addItems(self.rig.names)
            default = keep if keep in self.rig.names else (self.rig.depth_camera or self.rig.names[0])
            self.target_combo.setCurrentText(default)
        ok = self.rig is not None and self.recording is not None and self.rig.depth_camera is not None
        self.register_button.setEnabled(ok and not self._workers)

    def _update_labels(self) -> None:
        parts = []
        if self.rig_path is not None:
            parts.append(f"rig: {self.rig_path.name}")
        if self.recording_path is not None:
            parts.append(f"recording: {self.recording_path}")
        self.source_label.setText("   ".join(parts) or "Open a rig and a recording.")

    def _show_raw(self) -> None:
        titles = {L.name: _title(L, raw=True) for L in self.raw}
        self.raw_grid.set_layers([L.name for L in self.raw], titles)
        for L in self.raw:
            self.raw_grid.set_image(L.name, self.raw_renders[L.name])
        self.controls.set_layers(self.layers or self.raw)
        has_cube = any(L.bands > 3 for L in self.raw + self.layers)
        self.spectrum.setVisible(has_cube)
        self.spectrum_label.setVisible(has_cube)
        if not self._view_chosen:
            self.tabs.setCurrentWidget(self.raw_grid)

    # ------------------------------------------------------------------ registration
    def run_registration(self, target: str | None = None) -> None:
        """Register the open recording into ``target``'s view on a worker (reuses the meshes)."""
        target = target or self.target_combo.currentText() or (self.rig.depth_camera if self.rig else None)
        if any(getattr(w, "_kind", "") == "load" for w in self._workers):
            self._pending_target = target  # runs when the recording has been read
            self._update_empty_notes()
            return
        self._pending_target = None
        if self.rig is None or self.recording is None:
            show_error(self, "Cannot register", "Open a rig and a recording first.")
            return
        if target not in self.rig.names:
            show_error(self, "Cannot register",
                       f"unknown target camera '{target}'; the rig has {', '.join(self.rig.names)}")
            return
        if any(getattr(w, "_kind", "") == "register" for w in self._workers):
            return
        self.target_combo.setCurrentText(target)
        w = Worker(_register_job, self.registrar, self.rig, self.recording, target, dict(self.controls.settings))
        gen = self._generation
        self._start(w, f"Registering into {target}", lambda out: self._registered(out, gen), kind="register")

    def _registered(self, out: dict, generation: int | None = None) -> None:
        if generation is not None and generation != self._generation:
            return  # another rig or recording was opened meanwhile
        self.registrar = out["registrar"]
        self.result = r = out["result"]
        self.layers, self.renders, self.cloud = out["layers"], out["renders"], out["cloud"]
        names = [L.name for L in self.layers]
        self.sbs_grid.set_layers(names, {L.name: _title(L) for L in self.layers})
        for n in names:
            self.sbs_grid.set_image(n, self.renders[n])
        cams = [n for n in names if n != DEPTH]
        home, centre = _object_box(r.points_rig)
        self.sbs_grid.set_home(home)
        self.mosaic_view.view.set_home(home)
        self.masks_view.view.set_home(home)
        self.mosaic_view.set_renders(self.renders, cams, None if home is None else (int(home.height()), int(home.width())))
        self.masks_view.set_data(r.target, self.renders, names, r.cases, r.area)
        colour_by = next((L.name for L in self.layers if canonical_modality(L.modality) == "rgb"), r.target)
        self.cloud_view.set_cloud(self.cloud, out["meshes"], default=colour_by,
                                  note=f"Target {r.target}: object-mesh hits in the rig frame.")
        self.controls.set_layers(self.layers)
        self.controls.layer.setCurrentText(r.target)
        self.export_action.setEnabled(True)
        self.export_button.setEnabled(True)
        self.summary.setText(_summary_text(r))
        if not self._view_chosen:
            self.tabs.setCurrentWidget(self.sbs_grid)
        if centre is not None:  # start with the cursor on the object so every read-out has a value
            self._hover_target("start", *centre)
            self.cloud_view.pick(r.points_rig[centre])
        self._update_empty_notes()
        self.registered.emit(r)

    def cancel(self) -> None:
        self._pending_target = None
        for w in self._workers:
            w.cancel()

    # ------------------------------------------------------------------ export
    def _ask_export(self) -> None:
        if self.result is None:
            return
        start = self.last_export or self.default_export_folder()
        dlg = ExportDialog(start, self)
        if dlg.exec():
            self.export(dlg.out(), dlg.what())

    def default_export_folder(self) -> Path:
        """Beside the recording; for the demo, in the home folder: the demo lives in a temporary
        folder that is deleted when the window closes, and an export in it would go with it."""
        target = self.result.target if self.result is not None else "target"
        rec = self.recording_path
        demo = Path(self._demo_tmp.name).resolve() if self._demo_tmp is not None else None
        if rec is None or (demo is not None and demo in rec.resolve().parents):
            return Path.home() / f"plantreg-demo-registered-{target}" if rec is not None else Path.home()
        return rec.parent / f"registered-{target}"

    def export(self, out: str | Path, what: list[str] | None = None, overwrite: bool = False) -> bool:
        """Write the result with :func:`write_outputs` on a worker; asks before replacing a
        non-empty folder. Returns False when nothing was started."""
        from ...core.export import write_outputs

        if self.result is None:
            show_error(self, "Nothing to export", "Register the recording first.")
            return False
        out = Path(out)
        if folder_is_nonempty(out) and not overwrite:
            ans = QMessageBox.question(self, "Replace folder?",
                                       f"{out} exists and is not empty.\nReplace it with this export?",
                                       QMessageBox.StandardButton.Yes | QMessageBox.StandardButton.No,
                                       QMessageBox.StandardButton.No)
            if ans != QMessageBox.StandardButton.Yes:
                return False
            overwrite = True
        opts = {}
        for L in self.layers:
            if L.name == DEPTH:
                continue
            s = self.controls.settings_for(L.name)
            o: dict[str, Any] = {"percentiles": tuple(s.percentiles)}
            if s.cmap:
                o["cmap"] = s.cmap
            if s.bands is not None and L.bands > 3:
                o["bands"] = tuple(s.bands)
            opts[L.name] = o
        inputs = {"rig": str(self.rig_path)} if self.rig_path else None
        w = Worker(write_outputs, self.result, self.rig, self.recording, out, overwrite=overwrite, inputs=inputs,
                   what=what, display_options=opts)
        self._start(w, f"Exporting to {out}", self._exported, kind="export")
        return True

    def _exported(self, path: Any) -> None:
        self.last_export = Path(path)
        self.readout.setText(f"Exported to {path}")
        self.exported.emit(Path(path))

    # ------------------------------------------------------------------ workers
    def _start(self, w: Worker, title: str, on_done: Callable[[Any], None], kind: str = "load") -> None:
        w._kind = kind  # type: ignore[attr-defined]
        w._title = title  # type: ignore[attr-defined]
        self._workers.append(w)
        w.progress.connect(lambda f, m, t=title: self._progress(t, f, m))
        w.finished.connect(lambda out: self._guard(on_done, out, title="Cannot show the result"))
        w.failed.connect(lambda msg, det, t=title: show_error(self, t + " failed", msg, det))
        w.cancelled.connect(lambda t=title: self.readout.setText(f"{t}: cancelled."))
        w.done.connect(lambda w=w: self._worker_done(w))
        self.progress.setValue(0)
        self.progress.setFormat(f"{title} %p%")
        self.progress.show()
        self.cancel_button.show()
        self.register_button.setEnabled(False)
        w.start()
        self._update_empty_notes()

    def _progress(self, title: str, fraction: float, message: str) -> None:
        self.progress.setValue(int(round(fraction * 1000)))
        msg = f"{title}: {message}" if message else title
        self.progress.setFormat(msg.replace("%", "%%") + "  %p%")

    def _worker_done(self, w: Worker) -> None:
        if w in self._workers:
            self._workers.remove(w)
        w.deleteLater()
        if not self._workers:
            self.progress.hide()
            self.cancel_button.hide()
            self._fill_targets()
            if self._pending_target is not None:
                t, self._pending_target = self._pending_target, None
                if self.rig is not None and self.recording is not None:
                    self.run_registration(t)
            if not self._workers:
                self.idle.emit()
        self._update_empty_notes()

    def _guard(self, fn: Callable, *args: Any, title: str = "Cannot open") -> Any:
        try:
            return fn(*args)
        except PlantregError as e:
            show_error(self, title, str(e))
        return None

    # ------------------------------------------------------------------ file dialogs, recent, drops
    def _settings(self) -> QSettings:
        return QSettings("plantreg", "plantreg")

    def _ask_rig(self) -> None:
        p, _ = QFileDialog.getOpenFileName(self, "Open rig", str(self.rig_path or ""), "Rig files (*.json);;All (*)")
        if p:
            self.open_rig(p)

    def _ask_recording(self) -> None:
        d = QFileDialog.getExistingDirectory(self, "Open recording folder", str(self.recording_path or ""))
        if d:
            self.open_recording(d)

    def _ask_plant3d(self, folder: str | Path | None = None) -> None:
        if folder is None:
            folder = QFileDialog.getExistingDirectory(self, "Plant3DImageReg data set folder", "")
            if not folder:
                return
        plants = plant3d.list_plants(folder)
        plant, ok = QInputDialog.getItem(self, "Plant3DImageReg", "Plant", plants, 0, False)
        if ok and plant:
            self.open_plant3d(folder, plant)

    def recent(self) -> list[str]:
        v = self._settings().value(RECENT_KEY, [])
        return [str(x) for x in (v if isinstance(v, list) else [v] if v else [])]

    def _add_recent(self, kind: str, path: str) -> None:
        entry = f"{kind}:{path}"
        items = [entry] + [e for e in self.recent() if e != entry]
        self._settings().setValue(RECENT_KEY, items[:MAX_RECENT])

    def _fill_recent(self) -> None:
        self.recent_menu.clear()
        for e in self.recent():
            kind, _, path = e.partition(":")
            self.recent_menu.addAction(f"{kind}: {path}", lambda k=kind, p=path: self._guard(self._open_recent, k, p))
        if self.recent_menu.isEmpty():
            self.recent_menu.addAction("(none)").setEnabled(False)

    def _open_recent(self, kind: str, path: str) -> None:
        if kind == "rig":
            self.open_rig(path)
        elif kind == "recording":
            self.open_recording(path)
        elif kind == "plant3d":
            folder, _, plant = path.partition("|")
            self.open_plant3d(folder, plant)

    def dragEnterEvent(self, e) -> None:  # noqa: N802
        if e.mimeData().hasUrls():
            e.acceptProposedAction()

    def dropEvent(self, e) -> None:  # noqa: N802
        for url in e.mimeData().urls():
            self._guard(self.open_path, url.toLocalFile())
        e.acceptProposedAction()

    def open_path(self, path: str | Path) -> None:
        """Open whatever a dropped path is: a rig file, a recording folder, a demo folder
        (rig.json + recording/), or the Plant3DImageReg data set."""
        p = Path(path)
        if p.is_file() and p.suffix.lower() == ".json":
            if p.name == MANIFEST:
                self.open_recording(p.parent)
            else:
                self.open_rig(p)
        elif p.is_dir() and plant3d.is_dataset(p):
            self._ask_plant3d(p)
        elif p.is_dir() and (p / MANIFEST).is_file():
            self.open_recording(p)
        elif p.is_dir() and (p / "rig.json").is_file() and (p / "recording" / MANIFEST).is_file():
            self.rig = None
            self.open_rig(p / "rig.json")
            self.open_recording(p / "recording")
        else:
            raise InputError("not a rig file, a recording folder or the Plant3DImageReg data set", p)

    # ------------------------------------------------------------------ interaction
    def _tab_changed(self, _i: int) -> None:
        if self.tabs.currentWidget() is self.cloud_view:
            self.cloud_view.render_now()

    def _band_for(self, L: Layer) -> int | None:
        s = self.controls.settings_for(L.name)
        return s.bands[0] if s.bands is not None else (L.bands // 2 if L.bands > 3 else None)

    def _hover_target(self, _src: str, row: int, col: int) -> None:
        if row < 0 or not self.layers:
            return  # leaving the image keeps the last cursor and read-out (the pixel under study)
        self.sbs_grid.set_cursor(row, col)
        parts = [f"x={col} y={row}"]
        for L in self.layers:
            parts.append(f"{L.name}: {L.value_text(row, col, self._band_for(L))}")
        if self.result is not None:
            src = self.masks_view.source.currentText()
            if src in self.result.cases:
                from ...core.register import AREA_NAMES, CASE_NAMES

                parts.append(f"{src} case: {CASE_NAMES.get(int(self.result.cases[src][row, col]), '?')}")
                parts.append(f"area: {AREA_NAMES.get(int(self.result.area[row, col]), '?')}")
        self._set_readout("   ".join(parts))
        for L in self.layers:
            spec = L.spectrum(row, col)
            if spec is not None:
                self.spectrum.set_spectrum(spec, L.wavelengths, f"{L.name} at x={col}, y={row}")
                break

    def _hover_raw(self, name: str, row: int, col: int) -> None:
        L = next((x for x in self.raw if x.name == name), None)
        if L is None or row < 0:
            return
        self._set_readout(f"{name} (raw {L.data.shape[1]}x{L.data.shape[0]})  x={col} y={row}: "
                          f"{L.value_text(row, col, self._band_for(L))}")
        spec = L.spectrum(row, col)
        if spec is not None:
            self.spectrum.set_spectrum(spec, L.wavelengths, f"{name} (raw) at x={col}, y={row}")

    def _set_readout(self, text: str) -> None:
        self.readout_text = text
        self.readout.setText(text)

    def _display_changed(self, name: str, settings: DisplaySettings) -> None:
        for L in self.raw:
            if L.name == name:
                self.raw_renders[name] = render(L.data, L.modality, settings)
                self.raw_grid.set_image(name, self.raw_renders[name])
        for L in self.layers:
            if L.name == name:
                self.renders[name] = render(L.data, L.modality, settings)
                self.sbs_grid.set_image(name, self.renders[name])
                self.mosaic_view.update_view()
                self.masks_view.update_view()
                if self.cloud is not None:
                    self.cloud.colours[name] = self.renders[name].reshape(-1, 3)[self.cloud.pixels]
                    if self.cloud_view.colour.currentText() == name:
                        self.cloud_view._recolour()
        if self.plant is not None and self.cloud is not None and name in self.cloud.colours:
            self.cloud.colours[name] = self.raw_renders[name].reshape(-1, 3)[self.cloud.pixels]
            if self.cloud_view.colour.currentText() == name:
                self.cloud_view._recolour()


def _object_box(points_rig: np.ndarray, margin: float = 0.08) -> tuple[QRectF | None, tuple[int, int] | None]:
    """Bounding box (scene rect, with a margin) of the target pixels with an object hit, and the
    object pixel nearest the box centre as (row, col); (None, None) if nothing was hit."""
    ok = np.isfinite(points_rig[..., 2])
    rows, cols = np.nonzero(ok)
    if rows.size == 0:
        return None, None
    h, w = ok.shape
    r0, r1, c0, c1 = rows.min(), rows.max() + 1, cols.min(), cols.max() + 1
    m = margin * max(r1 - r0, c1 - c0)
    rect = QRectF(max(c0 - m, 0), max(r0 - m, 0), 0, 0)
    rect.setRight(min(c1 + m, w))
    rect.setBottom(min(r1 + m, h))
    rc, cc = (r0 + r1) / 2, (c0 + c1) / 2
    i = int(np.argmin((rows - rc) ** 2 + (cols - cc) ** 2))
    return rect, (int(rows[i]), int(cols[i]))


def _title(L: Layer, raw: bool = False) -> str:
    h, w = L.data.shape[:2]
    unit = f", {L.unit}" if L.unit else ""
    bands = f", {L.bands} bands" if L.bands > 3 else ""
    what = "z of the hit point" if (L.name == DEPTH and not raw) else L.modality
    return f"{L.name}  ({what}{unit}{bands}, {w}x{h})"


def _summary_text(r: Any) -> str:
    h, w = r.shape
    lines = [f"<b>Target {r.target}</b> ({w}x{h})"]
    if r.timings:
        stages = {k: v for k, v in r.timings.items() if k != "total"}
        total = r.timings.get("total", sum(stages.values()))
        top = sorted(stages.items(), key=lambda kv: -kv[1])[:4]
        lines.append(f"registration {total:.2f} s (slowest: " + ", ".join(f"{k} {v:.2f} s" for k, v in top) + ")")
    counts = r.case_counts()
    n = h * w
    for cam, cc in counts.items():
        p1 = cc.get(1, 0)
        obj = n - cc.get(0, 0)
        lines.append(f"{cam}: P1 {p1:,} ({100 * p1 / max(obj, 1):.1f}% of object), P2 {cc.get(2, 0):,}, "
                     f"P3.1 {cc.get(3, 0):,}, P3.2 {cc.get(4, 0):,}")
    return "<br>".join(lines)
