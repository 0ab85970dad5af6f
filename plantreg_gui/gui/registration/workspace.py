"""The registration workspace: a thin Qt shell around a :class:`~.session.RegistrationSession`.

The session (Qt-free) holds the rig, recording, result, layers, display settings, masks source
and cursor and emits events; the views (registered in :mod:`.views`) subscribe to it. This
widget owns only what is Qt's business: the toolbar and menus, the worker threads that run the
session's jobs (:class:`~plantreg_gui.gui.workers.Worker`), dialogs, recent files and drops.

Length: the window's menus, toolbar, views, drag and drop, recent files and jobs; the state
is in the Qt-free :class:`~.session.RegistrationSession`.
"""

from __future__ import annotations

import json
import shutil
import tempfile
from pathlib import Path
from typing import Any, Callable

from PySide6.QtCore import QEvent, QSettings, Qt, Signal
from PySide6.QtGui import QKeySequence
from PySide6.QtWidgets import (
    QComboBox, QFileDialog, QFrame, QInputDialog, QLabel, QMenu, QMessageBox, QProgressBar, QPushButton,
    QScrollArea, QSplitter,
    QStatusBar, QTabWidget, QToolBar, QToolButton, QVBoxLayout, QWidget,
)

from ...core.data import plant3d
from ...core.errors import InputError, PlantregError
from ...core.data.recording import MANIFEST
from ...core.camera.rig import Rig
from ...models.layers import DisplaySettings
from ...models.registration import (RegistrationSession, check_is_rig_file, demo_job, fit_problem, kind_of_path,
                                   load_job, plant3d_job, recording_for_plant, register_job, rig_beside)
from ..workers import Jobs, Worker, show_error
from .display_controls import DisplayControls
from .export_dialog import ExportDialog, folder_is_nonempty
from .image_views import SpectrumPlot
from .params_panel import ParamsPanel
from .region_panel import RegionPanel
from .views import VIEWS, view_key

RECENT_KEY = "workspace/recent"
DISPLAY_KEY = "workspace/display"
MAX_RECENT = 10


def _export_of_another(folder: Path, recording: Path | None) -> str:
    """A sentence for the replace question when ``folder`` holds an export of another recording
    (its summary.json names it); '' otherwise. One plant's export replacing another's is the
    mistake worth a second look."""
    import json

    try:
        rec = json.loads((folder / "summary.json").read_text(encoding="utf-8"))["inputs"]["recording"]
    except (OSError, ValueError, KeyError, TypeError):
        return ""
    if not isinstance(rec, str) or recording is None or Path(rec) == Path(recording):
        return ""
    return f"\nIt holds the registration of another recording, {Path(rec).name} ({rec}): that export would be lost."


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
    #: File > Fit rig from landmarks: (rig path or None, recording folder or None); the window opens the page
    landmarks_requested = Signal(object, object)

    def __init__(self, parent: QWidget | None = None, session: RegistrationSession | None = None):
        super().__init__(parent)
        self.setAcceptDrops(True)
        self.session = session or RegistrationSession()
        self.last_export: Path | None = None
        self._last_export_key: tuple | None = None  # (recording, target) of the last export
        self._workers = Jobs(self, on_progress=self._progress,
                             on_cancelled=lambda t: self.readout.setText(f"{t}: cancelled."),
                             on_end=self._worker_done)
        self._view_chosen = False
        self._demo_tmp: tempfile.TemporaryDirectory | None = None
        self._build_ui()
        ev = self.session.events
        ev.source.connect(self._source_changed)
        ev.raw.connect(self._raw_changed)
        ev.result.connect(self._result_changed)
        ev.cursor.connect(self._cursor_moved)
        ev.busy.connect(self._update_empty_notes)
        ev.display.connect(self._remember_display)

    # ------------------------------------------------------------------ the session's state, for callers
    rig = property(lambda self: self.session.rig)
    rig_path = property(lambda self: self.session.rig_path)
    recording = property(lambda self: self.session.recording)
    recording_path = property(lambda self: self.session.recording_path)
    plant = property(lambda self: self.session.plant)
    registrar = property(lambda self: self.session.registrar)
    result = property(lambda self: self.session.result)
    layers = property(lambda self: self.session.layers)
    renders = property(lambda self: self.session.renders)
    raw = property(lambda self: self.session.raw)
    raw_renders = property(lambda self: self.session.raw_renders)
    cloud = property(lambda self: self.session.cloud)
    readout_text = property(lambda self: self.session.readout)
    raw_grid = property(lambda self: self.views["raw"])
    sbs_grid = property(lambda self: self.views["side-by-side"])
    mosaic_view = property(lambda self: self.views["mosaic"])
    masks_view = property(lambda self: self.views["masks"])
    cloud_view = property(lambda self: self.views["3d"])

    # ------------------------------------------------------------------ UI
    def _build_ui(self) -> None:
        tb = QToolBar("Workspace")
        tb.setToolButtonStyle(Qt.ToolButtonStyle.ToolButtonTextOnly)
        self.file_menu = QMenu("File", self)
        self.file_menu.addAction("Open rig…", lambda: self._guard(self._ask_rig))
        self.file_menu.addAction("Open recording…", lambda: self._guard(self._ask_recording))
        self.file_menu.addAction("Open Plant3DImageReg recording…", lambda: self._guard(self._ask_plant3d))
        self.recent_menu = self.file_menu.addMenu("Open recent")
        self.close_action = self.file_menu.addAction("Close", self.close_sources)
        self.close_action.setToolTip("close the rig, the recording and the result (to open another pair)")
        self.recent_menu.aboutToShow.connect(self._fill_recent)
        self.file_menu.addAction("Fit rig from landmarks…", lambda: self.landmarks_requested.emit(
            self.rig_path, getattr(self.recording, "folder", None)))
        self.file_menu.addSeparator()
        self.file_menu.addAction("Load demo", lambda: self._guard(self.load_demo))
        self.export_action = self.file_menu.addAction("Export…", lambda: self._guard(self._ask_export,
                                                                                      title="Cannot export"))
        self.export_action.setEnabled(False)
        self.file_menu.addAction("Save region…", lambda: self._guard(self._ask_save_region, title="Cannot save"))
        self.file_menu.addAction("Load region…", lambda: self._guard(self._ask_load_region))
        self.save_view_action = self.file_menu.addAction("Save view as PNG…",
                                                         lambda: self._guard(self._ask_save_view, title="Cannot save"))
        self.save_view_action.setShortcut(QKeySequence("Ctrl+Shift+S"))
        self.save_view_action.setShortcutContext(Qt.ShortcutContext.WidgetWithChildrenShortcut)
        self.addAction(self.save_view_action)  # the shortcut works without opening the menu
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
        self.export_button.clicked.connect(lambda: self._guard(self._ask_export, title="Cannot export"))
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
        self.views: dict[str, QWidget] = {}
        for spec in VIEWS:
            w = spec.make(self.session)
            self.views[spec.key] = w
            self.tabs.addTab(w, spec.title)
        self.tabs.tabBarClicked.connect(lambda _i: setattr(self, "_view_chosen", True))
        self.empty_notes = {key: _EmptyNote(w) for key, w in self.views.items()}
        self.tabs.currentChanged.connect(self._tab_changed)

        self.controls = DisplayControls()
        self.controls.settings = self.session.display  # the session's settings, not a copy
        self.controls.changed.connect(self.session.set_display)
        self.spectrum = SpectrumPlot()
        self.summary = QLabel("")
        self.summary.setWordWrap(True)
        self.summary.setAlignment(Qt.AlignmentFlag.AlignTop | Qt.AlignmentFlag.AlignLeft)
        self.summary.setStyleSheet("font-size: 11px;")
        side = QWidget()
        sl = QVBoxLayout(side)
        sl.setContentsMargins(4, 0, 0, 0)
        sl.addWidget(self.controls)
        self.params_panel = ParamsPanel(self.session)
        sl.addWidget(self.params_panel)
        self.region_panel = RegionPanel(self.session)
        self.region_panel.tool_changed.connect(self._region_tool)
        self.region_panel.csv_button.clicked.connect(lambda: self._guard(self._ask_region_csv,
                                                                         title="Cannot save the statistics"))
        self._stats_worker: Worker | None = None  # the region statistics being computed
        self.session.stats_runner = self._run_region_stats  # a 4K cube's statistics take seconds
        sl.addWidget(self.region_panel)
        self.spectrum_label = QLabel("Spectrum under the cursor")
        sl.addWidget(self.spectrum_label)
        sl.addWidget(self.spectrum)
        sl.addWidget(self.summary, 1)
        self.spectrum.hide()  # shown once a multi-band image is open (an empty plot says nothing)
        self.spectrum_label.hide()
        side.setMinimumWidth(270)
        # the side panel scrolls when its groups are taller than the window (a region's spectrum
        # below the cursor's): its content never makes the window taller than the screen
        self.side_scroll = QScrollArea()
        self.side_scroll.setWidget(side)
        self.side_scroll.setWidgetResizable(True)
        self.side_scroll.setFrameShape(QFrame.Shape.NoFrame)
        self.side_scroll.setHorizontalScrollBarPolicy(Qt.ScrollBarPolicy.ScrollBarAlwaysOff)
        self.side_scroll.setMinimumWidth(280)
        self.side_scroll.setMaximumWidth(375)

        split = QSplitter(Qt.Orientation.Horizontal)
        split.addWidget(self.tabs)
        split.addWidget(self.side_scroll)
        split.setStretchFactor(0, 1)
        split.setStretchFactor(1, 0)
        split.setChildrenCollapsible(False)

        self.status = QStatusBar()
        self.status.setSizeGripEnabled(False)
        self.readout = QLabel("")
        self.readout.setTextInteractionFlags(Qt.TextInteractionFlag.TextSelectableByMouse)
        self.readout.setMinimumWidth(10)  # a long read-out never widens the window ...
        # ... it wraps onto a second line (the cursor's read-out of five cameras with case and area
        # was cut at 1280 px); two lines always, so the views keep their size
        self.readout.setWordWrap(True)
        self.readout.setFixedHeight(2 * self.readout.fontMetrics().lineSpacing() + 2)
        self.status.addWidget(self.readout, 1)
        self.progress = QProgressBar()
        self.progress.setRange(0, 1000)
        self.progress.setMinimumWidth(360)
        self.progress.setMaximumWidth(520)  # long progress messages are elided, never widen the window
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

    # ------------------------------------------------------------------ reacting to the session
    def _update_empty_notes(self) -> None:
        """Say in every empty view why it is empty and what fills it."""
        for key, note in self.empty_notes.items():
            note.show_text(self.session.empty_note(getattr(self.views[key], "needs", "result")))

    def _source_changed(self) -> None:
        s = self.session
        self._fill_targets()
        self.params_panel.setEnabled(s.can_register())  # nothing to tune without a rig and a recording
        if s.plant is not None:
            p = s.plant
            missing = f" Not in the data set: {', '.join(p.missing)}." if p.missing else ""
            self.banner.setText(p.note + missing)
            self.banner.show()
            self.source_label.setText(f"Plant3DImageReg: {p.plant}  ({p.folder})")
        else:
            parts = []
            if s.rig_path is not None:
                parts.append(f"rig: {s.rig_path.name}")
            if s.recording_path is not None:
                parts.append(f"recording: {s.recording_path}")
            self.source_label.setText("   ".join(parts) or "Open a rig and a recording.")
            if s.recording is not None and s.rig is None:
                self.banner.setText("No rig is open: the raw images are shown; open the rig file "
                                    "(File ▸ Open rig…) to register them.")
                self.banner.show()
            else:
                self.banner.hide()
        self._update_empty_notes()

    def _raw_changed(self) -> None:
        s = self.session
        self.controls.set_layers(s.layers or s.raw)
        has_cube = s.has_cube()
        self.spectrum.setVisible(has_cube)
        self.spectrum_label.setVisible(has_cube)
        if not self._view_chosen:
            self.tabs.setCurrentWidget(self.views["raw"])
        self._update_empty_notes()

    def _result_changed(self) -> None:
        s = self.session
        r = s.result
        ok = r is not None
        self.export_action.setEnabled(ok)
        self.export_button.setEnabled(ok)
        self.summary.setText(s.summary_html())
        self.controls.set_layers(s.layers or s.raw)
        if ok:
            self.controls.layer.setCurrentText(r.target)
            warnings = list(getattr(r, "warnings", []) or [])
            if warnings:  # e.g. the ROI cuts off most of the measured depth (core/geometry/roi.py)
                self.banner.setText(" ".join(warnings))
                self.banner.show()
            elif s.plant is None and s.rig is not None:
                self.banner.hide()
            if not self._view_chosen:
                self.tabs.setCurrentWidget(self.views["side-by-side"])
        self._update_empty_notes()

    def _cursor_moved(self) -> None:
        s = self.session
        self.readout.setText(s.readout)
        self.readout.setToolTip(s.readout)
        if s.spectrum is not None:
            self.spectrum.set_spectrum(*s.spectrum)
        elif s.cursor is None:  # other data opened: the last spectrum was of the old data
            self.spectrum.set_spectrum(None, None, "")

    # ------------------------------------------------------------------ contract for main_window
    def is_busy(self) -> bool:
        return bool(self._workers) or self.session.is_busy()

    def set_view(self, name: str) -> None:
        key = view_key(name)
        if key is None:
            raise InputError(f"unknown view '{name}'; choose from {', '.join(v.key for v in VIEWS)}")
        self._view_chosen = True
        self.tabs.setCurrentWidget(self.views[key])

    def current_view(self) -> str:
        w = self.tabs.currentWidget()
        return next(k for k, v in self.views.items() if v is w)

    def _hook(self, name: str, *views: Any) -> None:
        """Call the optional hook ``name`` of ``views`` (default: every view; see views.py)."""
        for v in views or tuple(self.views.values()):
            fn = getattr(v, name, None)
            if fn is not None:
                fn()

    def prepare_screenshot(self) -> None:
        self._hook("prepare_screenshot", self.tabs.currentWidget())

    def shutdown(self) -> None:
        self.session.pending_target = None
        self._workers.wait_all(30000)
        self._hook("shutdown")
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
        self.session.pending_target = target or "ir"
        self._start(Worker(demo_job, folder, self._job_settings()), "Preparing the demo",
                    self._loaded)

    def close_sources(self) -> None:
        """File ▸ Close: stop the jobs and forget rig, recording (or plant) and result."""
        self.cancel()
        self.session.close()
        self.readout.setText("")

    def _confirm(self, title: str, text: str) -> bool:
        return QMessageBox.question(self, title, text, QMessageBox.StandardButton.Yes | QMessageBox.StandardButton.No,
                                    QMessageBox.StandardButton.No) == QMessageBox.StandardButton.Yes

    def open_rig(self, path: str | Path) -> None:
        """Read a rig file (raises :class:`InputError` naming the file if it is bad). A shown
        Plant3DImageReg plant is reopened through the recording that ships with the rig (see
        :func:`recording_for_plant`); an open recording that does not fit the rig is closed
        when the user agrees."""
        path = Path(path)
        if path.is_dir():
            raise InputError("is a folder, not a rig file: choose the rig's .json file", path)
        check_is_rig_file(path)
        rig = Rig.load(path)
        s = self.session
        if s.plant is not None:
            rec = recording_for_plant(path, s.plant.plant)
            plant = s.plant.plant
            s.close()  # a plant of the data set has no rig of its own
            if rec is not None:
                self._add_recent("rig", str(path))
                self._start(Worker(load_job, path, rec, None, self._job_settings()), f"Reading {plant}",
                            self._loaded)
                return
            self.readout.setText(f"{plant} closed: the rig has no recording of it (recordings/{plant} "
                                 "beside the rig); open its recording folder.")
        elif s.recording is not None:
            why = fit_problem(rig, s.recording)
            if why is not None:
                if not self._confirm("Close the recording?",
                                     f"The open recording {s.recording_path} does not fit this rig:\n{why}\n\n"
                                     "Close the recording and open the rig?"):
                    return
                s.close()
        s.set_rig(rig, path)
        self._add_recent("rig", str(path))

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
        rig_path = rig_beside(path) if self.session.rig is None else None
        self._start(Worker(load_job, rig_path, path, self.session.rig, self._job_settings()),
                    "Reading the recording", self._loaded)

    def open_plant3d(self, folder: str | Path, plant: str) -> None:
        """Open one plant of the Plant3DImageReg data set (raw images + nominal depth cloud)."""
        folder = Path(folder)
        if plant not in plant3d.list_plants(folder):
            raise InputError(f"no plant '{plant}' in the data set", folder)
        rec = recording_for_plant(self.session.rig_path, plant)
        if rec is not None:  # the open rig ships a recording of this plant: that one registers
            self.open_recording(rec)
            return
        self._start(Worker(plant3d_job, folder, plant, self._job_settings()),
                    f"Reading {plant}", self._plant_loaded)

    def _loaded(self, out: dict) -> None:
        s = self.session
        if out.get("misfit"):
            old = s.rig_path.name if s.rig_path is not None else "the open rig"
            if not self._confirm("Close the rig?",
                                 f"The recording {out['recording_path']} does not fit {old}:\n{out['misfit']}\n\n"
                                 "Close the rig and show the recording's raw images?"):
                return
        s.apply_loaded(out)
        if out.get("replaced_rig"):
            self.readout.setText(f"Opened with its own rig {out['rig_path']} (the open rig did not fit: "
                                 f"{out['replaced_rig']})")
        if not out.get("demo"):  # the demo lives in a temporary folder: not worth remembering
            if s.rig_path is not None:
                self._add_recent("pair", f"{s.rig_path}|{out['recording_path']}")
            else:
                self._add_recent("recording", str(out["recording_path"]))

    def _plant_loaded(self, out: dict) -> None:
        old_rig = self.session.rig_path
        self.session.apply_plant(out)
        if old_rig is not None:  # said, not silent: the plant has no recording for this rig
            self.readout.setText(f"Rig {old_rig.name} closed: it ships no recording of {out['plant'].plant} "
                                 "(recordings/<plant> beside the rig file).")
        p = out["plant"]
        self._add_recent("plant3d", f"{p.folder}|{p.plant}")
        if not self._view_chosen:
            self.tabs.setCurrentWidget(self.views["raw"])

    def _fill_targets(self) -> None:
        s = self.session
        keep = self.target_combo.currentText()
        self.target_combo.clear()
        if s.rig is not None:
            self.target_combo.addItems(s.rig.names)
            default = keep if keep in s.rig.names else (s.rig.depth_camera or s.rig.names[0])
            self.target_combo.setCurrentText(default)
        self.register_button.setEnabled(s.can_register() and not self._workers)

    # ------------------------------------------------------------------ registration
    def run_registration(self, target: str | None = None) -> None:
        """Register the open recording into ``target``'s view on a worker (reuses the meshes)."""
        s = self.session
        target = target or self.target_combo.currentText() or (s.rig.depth_camera if s.rig else None)
        if s.busy_with("load"):
            s.pending_target = target  # runs when the recording has been read
            self._update_empty_notes()
            return
        s.pending_target = None
        try:
            s.check_target(target)
        except InputError as e:
            show_error(self, "Cannot register", str(e))
            return
        if s.busy_with("register"):
            return
        self.target_combo.setCurrentText(target)
        w = Worker(register_job, s.registrar, s.rig, s.recording, target, dict(s.display), params=s.params)
        gen = s.generation
        self._start(w, f"Registering into {target}", lambda out: self._registered(out, gen), kind="register")

    def _registered(self, out: dict, generation: int | None = None) -> None:
        if self.session.apply_registered(out, generation):
            self.registered.emit(out["result"])

    def cancel(self) -> None:
        self.session.pending_target = None
        self._workers.cancel_all()
        if self.session.result is not None:  # the toolbar names the target of what is shown
            self.target_combo.setCurrentText(self.session.result.target)

    # ------------------------------------------------------------------ export
    def _ask_export(self) -> None:
        if self.session.result is None:
            return
        # the last export's folder is offered again only for the same recording and target
        last = self.last_export if self._last_export_key == self._export_key() else None
        start = last or self.default_export_folder()
        dlg = ExportDialog(start, self)
        if dlg.exec():
            self.export(dlg.out(), dlg.what(), drop_mixed=dlg.drop_mixed())

    def default_export_folder(self) -> Path:
        return self.session.default_export_folder()

    def _export_key(self) -> tuple:
        r = self.session.result
        return (self.session.recording_path, None if r is None else r.target)

    def export(self, out: str | Path, what: list[str] | None = None, overwrite: bool = False,
               drop_mixed: bool = False) -> bool:
        """Write the result with the pipeline's :func:`~plantreg_gui.core.pipeline.pipeline.export`
        (as ``plantreg register`` does) on a worker; asks before replacing a non-empty folder.
        ``drop_mixed``: NaN where a pixel is flagged mixed (the shown result is not changed).
        Returns False when nothing was started."""
        from ...core.pipeline.pipeline import OutputOptions, export

        s = self.session
        if s.result is None:
            show_error(self, "Nothing to export", "Register the recording first.")
            return False
        out = Path(out)
        from ...core.io.paths import check_output_location

        from ...core.data.recording import recording_inputs

        # the inputs as `plantreg register` lists them (the folder, its manifest, every file it names)
        keep = [p for p in (s.rig_path, s.recording_path) if p is not None]
        if s.recording_path is not None:
            keep += recording_inputs(s.recording_path)
        if s.recording is not None:
            keep += [Path(p) for p in s.recording.paths.values()]
        # the one output check, before "Replace it?" rather than after Yes (the dialog asks about a non-empty folder)
        check_output_location(out, "output", folder=True, overwrite=True, inputs=keep, replace_flag=None)
        if folder_is_nonempty(out) and not overwrite:
            ans = QMessageBox.question(self, "Replace folder?",
                                       f"{out} exists and is not empty.{_export_of_another(out, s.recording_path)}"
                                       "\nReplace it with this export?",
                                       QMessageBox.StandardButton.Yes | QMessageBox.StandardButton.No,
                                       QMessageBox.StandardButton.No)
            if ans != QMessageBox.StandardButton.Yes:
                return False
            overwrite = True
        inputs = {"rig": str(s.rig_path)} if s.rig_path else None
        options = OutputOptions(parts=None if what is None else tuple(what), drop_mixed=drop_mixed,
                                display_options=s.export_display_options(),
                                mosaic_tile=self.mosaic_view.tile.value())  # the export's mosaic is the screen's
        w = Worker(export, s.result, s.rig, s.recording, out, options, overwrite=overwrite, inputs=inputs)
        self._start(w, f"Exporting to {out}", self._exported, kind="export")
        return True

    def _exported(self, path: Any) -> None:
        self.last_export = Path(path)
        self._last_export_key = self._export_key()
        self.readout.setText(f"Exported to {path}")
        self.exported.emit(Path(path))

    # ------------------------------------------------------------------ workers
    def _start(self, w: Worker, title: str, on_done: Callable[[Any], None], kind: str = "load") -> None:
        self.progress.setValue(0)
        self._progress(title, 0.0, "")
        self.progress.show()
        self.cancel_button.show()
        self.register_button.setEnabled(False)
        self._workers.start(w, title, lambda out: self._guard(on_done, out, title="Cannot show the result"))
        self.session.job_started(id(w), kind, title)

    def _progress(self, title: str, fraction: float, message: str) -> None:
        self.progress.setValue(int(round(fraction * 1000)))
        msg = f"{title}: {message}" if message else title
        self.progress.setToolTip(msg)
        # elide: the bar keeps its width whatever the message (a long path would widen the window)
        fm = self.progress.fontMetrics()
        room = max(self.progress.width(), self.progress.minimumWidth()) - fm.horizontalAdvance("  100%") - 16
        msg = fm.elidedText(msg, Qt.TextElideMode.ElideMiddle, max(room, 40))
        self.progress.setFormat(msg.replace("%", "%%") + "  %p%")

    def _worker_done(self, w: Worker) -> None:
        w.deleteLater()
        s = self.session
        s.job_ended(id(w))
        if not self._workers:
            self.progress.hide()
            self.cancel_button.hide()
            self._fill_targets()
            if s.pending_target is not None:
                t, s.pending_target = s.pending_target, None
                if s.rig is not None and s.recording is not None:
                    self.run_registration(t)
        if not self._workers and not s.is_busy():
            self.idle.emit()

    def _guard(self, fn: Callable, *args: Any, title: str = "Cannot open") -> Any:
        try:
            return fn(*args)
        except PlantregError as e:
            show_error(self, title, str(e))
        return None

    # ------------------------------------------------------------------ display settings remembered
    def _remember_display(self, name: str) -> None:
        """Colour map and limits per camera name survive the session (QSettings), so the next
        recording of the same rig is drawn the same way; absolute limits only when locked; band
        choices depend on the cube and are not kept."""
        st = self.session.settings_for(name)
        d = {"cmap": st.cmap, "percentiles": list(st.percentiles)}
        if st.locked and st.limits is not None:  # locked absolute limits hold for every recording
            d.update(limits=list(st.limits), locked=True)
        self._settings().setValue(f"{DISPLAY_KEY}/{name}", json.dumps(d))

    def remembered_display(self) -> dict[str, DisplaySettings]:
        qs = self._settings()
        qs.beginGroup(DISPLAY_KEY)
        out = {}
        for name in qs.childKeys():
            try:
                d = json.loads(str(qs.value(name)))
                lo, hi = (float(x) for x in d["percentiles"])
                if 0.0 <= lo < hi <= 100.0:
                    st = DisplaySettings(d.get("cmap") or None, (lo, hi))
                    if d.get("locked") and d.get("limits"):
                        a, b = (float(x) for x in d["limits"])
                        if a < b:
                            st = st.with_(limits=(a, b), locked=True)
                    out[name] = st
            except (ValueError, KeyError, TypeError):
                continue  # a damaged entry is ignored, not fatal
        qs.endGroup()
        return out

    def _job_settings(self) -> dict[str, DisplaySettings]:
        """Display settings for a job that renders: this session's, else the remembered ones."""
        self.session.release_unlocked_limits()  # every job that renders reads a new recording
        for name, st in self.remembered_display().items():
            self.session.display.setdefault(name, st)
        return dict(self.session.display)

    # ------------------------------------------------------------------ file dialogs, recent, drops
    def _settings(self) -> QSettings:
        return QSettings("plantreg", "plantreg")

    def _ask_rig(self) -> None:
        p, _ = QFileDialog.getOpenFileName(self, "Open rig", str(self.session.rig_path or ""),
                                           "Rig files (*.json);;All (*)")
        if p:
            self.open_rig(p)

    def _ask_recording(self) -> None:
        d = QFileDialog.getExistingDirectory(self, "Open recording folder", str(self.session.recording_path or ""))
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
        items = [str(x) for x in (v if isinstance(v, list) else [v] if v else [])]
        # an entry whose file is gone (e.g. a demo an older version remembered) would only fail later
        return [e for e in items if Path(e.partition(":")[2].partition("|")[0]).exists()]

    def _add_recent(self, kind: str, path: str) -> None:
        # absolute paths: a path typed relative to one folder is gone when the app starts from
        # another (the desktop menu), and the entry vanished from the list
        def _abs(p: str) -> str:
            return str(Path(p).expanduser().absolute())

        first, _, second = path.partition("|")
        if kind == "pair":
            path = f"{_abs(first)}|{_abs(second)}"
        elif kind == "plant3d":
            path = f"{_abs(first)}|{second}"  # a folder and a plant's name
        else:
            path = _abs(path)
        entry = f"{kind}:{path}"
        items = [entry] + [e for e in self.recent() if e != entry]
        self._settings().setValue(RECENT_KEY, items[:MAX_RECENT])

    def _fill_recent(self) -> None:
        self.recent_menu.clear()
        for e in self.recent():
            kind, _, path = e.partition(":")
            if kind == "pair":
                rig, _, rec = path.partition("|")
                label = f"{Path(rig).parent.name}/{Path(rig).name} + {Path(rec).parent.name}/{Path(rec).name}"
            else:
                label = f"{kind}: {path}"
            act = self.recent_menu.addAction(label, lambda k=kind, p=path: self._guard(self._open_recent, k, p))
            act.setToolTip(path.replace("|", " + "))
        if self.recent_menu.isEmpty():
            self.recent_menu.addAction("(none)").setEnabled(False)

    def open_pair(self, rig_path: str | Path, recording: str | Path) -> None:
        """Close what is open and read a rig and a recording together (File ▸ Open recent)."""
        rig_path, recording = Path(rig_path), Path(recording)
        check_is_rig_file(rig_path)
        self.close_sources()
        self._start(Worker(load_job, rig_path, recording, None, self._job_settings()), "Reading the recording",
                    self._loaded)

    def _open_recent(self, kind: str, path: str) -> None:
        if kind == "pair":
            rig, _, rec = path.partition("|")
            self.open_pair(rig, rec)
        elif kind == "rig":
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
        """Open whatever a dropped path is (the session's :func:`kind_of_path` says what)."""
        p = Path(path)
        kind = kind_of_path(p)
        if kind == "rig":
            self.open_rig(p)
        elif kind == "manifest":
            self.open_recording(p.parent)
        elif kind == "dataset":
            self._ask_plant3d(p)
        elif kind == "recording":
            self.open_recording(p)
        else:  # a demo folder: rig.json + recording/
            self.open_pair(p / "rig.json", p / "recording")

    # ------------------------------------------------------------------ interaction
    def _tab_changed(self, _i: int) -> None:
        self._hook("on_shown", self.tabs.currentWidget())

    # ------------------------------------------------------------------ save the view
    def _ask_save_view(self) -> None:
        key = self.current_view()
        start = (self.session.recording_path.parent if self.session.recording_path and not self.session.is_demo
                 else Path.home()) / f"plantreg-{key}.png"
        p, _ = QFileDialog.getSaveFileName(self, "Save view as PNG", str(start), "PNG image (*.png)")
        if p:
            self.save_view_png(p if p.lower().endswith(".png") else p + ".png")

    def save_view_png(self, path: str | Path) -> Path:
        """Save the shown view as a PNG: a 2D view as drawn on screen (images, titles, colour bars),
        the 3D view as its rendered scene at the window's size. Returns the path."""
        from ...core.io.imageio import write_png

        path = Path(path)
        key = self.current_view()
        w = self.views[key]
        if hasattr(w, "view_rgb"):
            rgb = w.view_rgb()
            if rgb is None:
                raise InputError(f"the {key} view has nothing to show yet; register first", path)
        else:
            from .image_views import rgb8_from_qimage

            rgb = rgb8_from_qimage(w.grab().toImage())
        try:
            write_png(path, rgb)  # the core's writer: atomic, nothing half-written
        except OSError as e:
            raise InputError(f"cannot write the PNG ({e.strerror or e})", path) from None
        self.readout.setText(f"Saved the {key} view to {path}")
        return path

    def _run_region_stats(self, job: tuple, token: int) -> None:
        stale = self._stats_worker  # a new region or source: the statistics still running are stale
        if stale is not None and stale in self._workers:
            stale.supersede()  # not "cancelled" in the status bar: its successor is running
        w = self._stats_worker = Worker(*job)
        self._start(w, "Region statistics", lambda out: self.session.apply_region_stats(out[0], token),
                    kind="region")

    def save_region(self, path: str | Path) -> Path:
        """Write the drawn region (shape, target camera and size) as JSON; raises without one."""
        from ...core.io.imageio import atomic_write_text
        from ...models.registration import region_to_json

        s = self.session
        if s.region is None or s.result is None:
            raise InputError("draw a region on the registered images first")
        path = Path(path)
        try:
            atomic_write_text(path, region_to_json(s.region, s.result.target, s.result.shape))
        except OSError as e:
            raise InputError(f"cannot write the region ({e.strerror or e})", path) from None
        self.readout.setText(f"Saved the region to {path}")
        return path

    def load_region(self, path: str | Path) -> None:
        """Draw the region saved in ``path`` again (same target camera and size), with its statistics."""
        from ...models.registration import region_from_json

        s = self.session
        path = Path(path)
        if s.result is None:
            raise InputError("register first: a region is drawn on the registered images", path)
        try:
            text = path.read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as e:
            raise InputError(f"cannot read the region file ({getattr(e, 'strerror', None) or e})", path) from None
        s.set_region(*region_from_json(text, s.result.target, s.result.shape, path))
        self.set_view("side-by-side")
        self.readout.setText(f"Loaded the region from {path}")  # not the last save's message

    def _region_dialog_start(self) -> str:
        rec = self.session.recording_path
        return str((rec.parent if rec is not None and not self.session.is_demo else Path.home()) / "region.json")

    def _ask_save_region(self) -> None:
        p, _ = QFileDialog.getSaveFileName(self, "Save region", self._region_dialog_start(), "Region (*.json)")
        if p:
            self.save_region(p if p.lower().endswith(".json") else p + ".json")

    def _ask_load_region(self) -> None:
        p, _ = QFileDialog.getOpenFileName(self, "Load region", self._region_dialog_start(), "Region (*.json)")
        if p:
            self.load_region(p)

    def _ask_region_csv(self) -> None:
        job = self.session.region_csv_job()  # raises (shown) without a region
        p, _ = QFileDialog.getSaveFileName(self, "Save region statistics", str(Path.home() / "region.csv"),
                                           "CSV (*.csv)")
        if not p:
            return
        path = Path(p if p.lower().endswith(".csv") else p + ".csv")

        def write(text: str) -> None:
            from ...core.io.imageio import atomic_write_text

            try:
                atomic_write_text(path, text)
            except OSError as e:
                raise InputError(f"cannot write the CSV ({e.strerror or e})", path) from None
            self.readout.setText(f"Saved the region statistics to {path}")

        self._start(Worker(*job), "Region statistics (CSV)", write, kind="region")

    def _region_tool(self, mode: str | None) -> None:
        """Regions are drawn on the registered images: draw mode on there, and show them."""
        self.sbs_grid.set_draw_mode(mode)
        if mode is not None:
            self.set_view("side-by-side")

