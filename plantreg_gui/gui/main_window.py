"""The main window: a registration workspace and a calibration wizard, one tab each."""

from __future__ import annotations

import sys
import time
from pathlib import Path
from typing import Callable

from PySide6.QtCore import Qt, QTimer
from PySide6.QtGui import QIcon
from PySide6.QtWidgets import QApplication, QMainWindow, QMenu, QTabWidget, QToolButton

from .. import __version__, resources
from ..core.errors import PlantregError


class MainWindow(QMainWindow):
    def __init__(self) -> None:
        super().__init__()
        self.setWindowTitle(f"plantreg {__version__}")
        self.setWindowIcon(QIcon(str(resources.path(resources.ICON))))
        self.tabs = QTabWidget(self)
        self.tabs.setDocumentMode(True)
        # Help in the tab bar's corner (no menu bar row: the window must fit small screens)
        self.help_menu = QMenu("Help", self)
        self.about_action = self.help_menu.addAction("About plantreg…", self.show_about)
        hb = QToolButton()
        hb.setText("Help")
        hb.setMenu(self.help_menu)
        hb.setPopupMode(QToolButton.ToolButtonPopupMode.InstantPopup)
        hb.setAutoRaise(True)
        self.tabs.setCornerWidget(hb)
        self.setCentralWidget(self.tabs)
        from .registration.workspace import RegistrationWorkspace
        from .calibration.wizard import CalibrationWizard

        self.workspace = RegistrationWorkspace(self)
        self.workspace.landmarks_requested.connect(self.show_landmarks)
        self.wizard = CalibrationWizard(self)
        self.tabs.addTab(self.workspace, "Registration")
        self.tabs.addTab(self.wizard, "Calibration")
        from .landmarks.page import LandmarkPage

        self.landmarks = LandmarkPage(self)
        self.tabs.addTab(self.landmarks, "Landmarks")
        self.statusBar()
        self._discard_confirmed = False  # the user agreed to lose unsaved landmark work on quit

    # ------------------------------------------------------------------ start options
    def apply_start_options(self, args) -> None:
        if getattr(args, "landmarks", None):
            if not args.rig:
                from ..core.errors import InputError

                raise InputError("--landmarks needs --rig (the start rig)")
            self.tabs.setCurrentWidget(self.landmarks)
            self.landmarks.open(args.rig, args.landmarks, [args.recording] if args.recording else None)
        elif args.calibrate_demo or args.session:
            self.tabs.setCurrentWidget(self.wizard)
            if args.calibrate_demo:
                self.wizard.load_demo()
            else:
                self.wizard.open_session(args.session)
            if args.page:
                self.wizard.go_to_page(args.page)
        elif args.demo or args.rig or args.recording:
            self.tabs.setCurrentWidget(self.workspace)
            if args.demo:
                self.workspace.load_demo(target=args.target)
            else:
                if args.rig:
                    self.workspace.open_rig(args.rig)
                if args.recording:
                    self.workspace.open_recording(args.recording)
                if args.target and args.rig and args.recording:
                    self.workspace.run_registration(args.target)
            if args.view:
                self.workspace.set_view(args.view)

    def is_busy(self) -> bool:
        return self.workspace.is_busy() or self.wizard.is_busy() or self.landmarks.is_busy()

    def busy_for_screenshot(self) -> bool:
        """Busy with work the shown view needs (the wizard's page 1 does not wait for detection)."""
        return self.workspace.is_busy() or self.wizard.page_busy() or self.landmarks.is_busy()

    # ------------------------------------------------------------------ screenshots
    def screenshot_when_idle(self, path: Path, timeout: float,
                             done: Callable[[int], None] | None = None) -> None:
        """Poll until no view is busy (and stays idle briefly), then grab the window and call
        ``done(exit code)``: 0 saved, 1 an error dialog was shown, 3 timed out. ``plantreg-gui
        --screenshot`` passes ``QApplication.exit``; the window itself never quits the application
        (a quit application makes every later nested event loop return at once)."""
        from .workers import SHOWN_ERRORS

        t0 = time.monotonic()
        state = {"idle_since": None}
        n_errors = len(SHOWN_ERRORS)

        def tick() -> None:
            now = time.monotonic()
            if self.busy_for_screenshot() and now - t0 < timeout:
                state["idle_since"] = None
                return
            if state["idle_since"] is None:
                state["idle_since"] = now
                return
            if now - state["idle_since"] < 0.5 and now - t0 < timeout:
                return
            timer.stop()
            errors = []
            try:
                self.save_screenshot(path)
            except (OSError, PlantregError) as e:  # a full disk, a folder made read-only meanwhile
                from ..core.errors import show_path

                where = f"{show_path(e.filename)}: " if isinstance(e, OSError) and e.filename else ""
                errors.append(("Screenshot not saved", f"{where}{e.strerror if isinstance(e, OSError) else e}"))
            errors = SHOWN_ERRORS[n_errors:] + errors
            for title, msg in errors:  # shown in a dialog nobody will see: say it and fail
                print(f"plantreg-gui: error: {title}: {msg}", file=sys.stderr)
            if done is not None:
                done(1 if errors else 0 if now - t0 < timeout else 3)

        timer = QTimer(self)
        timer.timeout.connect(tick)
        timer.start(100)
        self._screenshot_timer = timer

    def save_screenshot(self, path: Path) -> None:
        for w in (self.workspace, self.wizard):
            prep = getattr(w, "prepare_screenshot", None)
            if prep is not None:
                prep()
        from .resize_hold import release_all

        release_all()  # views resized a moment ago draw at their size now
        QApplication.processEvents()
        import errno

        from ..core.io.imageio import atomic_path

        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        with atomic_path(path) as tmp:  # the one atomic writer: never half a PNG, never a special file
            if not self.grab().save(str(tmp), "PNG"):  # Qt says False, never why
                raise OSError(errno.EIO, "the PNG could not be written", str(tmp))
        print(f"screenshot saved to {path}")

    def closeEvent(self, event) -> None:  # noqa: N802 (Qt name)
        if not self._discard_confirmed:  # app.py closes the window again after the loop
            if not self.landmarks.confirm_discard("Quit"):
                event.ignore()
                return
            self._discard_confirmed = True
        for w in (self.workspace, self.wizard, self.landmarks):
            w.shutdown()
        super().closeEvent(event)

    def open_paths(self) -> list[tuple[str, Path | None]]:
        """[(label, path)] of the files each page has open (None: nothing open), for About."""
        wz = getattr(getattr(self.wizard, "model", None), "session", None)
        lm = getattr(self.landmarks, "session", None)
        return [("rig", self.workspace.rig_path), ("recording", self.workspace.recording_path),
                ("calibration session", getattr(wz, "folder", None)),
                ("landmarks file", getattr(getattr(lm, "landmarks", None), "path", None))]

    def show_about(self) -> None:
        from .about import AboutDialog

        dlg = AboutDialog(self, self.open_paths())
        dlg.setAttribute(Qt.WidgetAttribute.WA_DeleteOnClose)
        self.about_dialog = dlg
        dlg.open()

    def show_landmarks(self, rig_path: Path | None, recording: Path | None) -> None:
        """The workspace's File ▸ "Fit rig from landmarks…": the landmark page on its rig and recording."""
        from PySide6.QtWidgets import QFileDialog

        from ..core.errors import PlantregError
        from .workers import show_error

        self.tabs.setCurrentWidget(self.landmarks)
        if rig_path is None or not self.landmarks.confirm_discard("Open another rig"):
            return
        lm, _ = QFileDialog.getSaveFileName(self, "Landmarks file (new or existing)",
                                            str(Path(rig_path).parent / "landmarks.json"), "Landmarks (*.json)",
                                            options=QFileDialog.Option.DontConfirmOverwrite)
        if lm:
            try:
                self.landmarks.open(rig_path, lm, [recording] if recording else None)
            except PlantregError as e:
                show_error(self, "Cannot open", str(e))
