"""What a wizard page may depend on: the wizard model and a narrow actions interface.

A page reads state from :class:`~.model.WizardModel` and changes it only through the model's
methods (each emits a change signal that every interested page receives). Work that needs a
worker (detection, calibration, saving) or navigation is asked for through
:class:`WizardActions`; a page never reaches into the wizard's or another page's widgets.

Pages redraw only when visible: :meth:`WizardPage.refresh_later` refreshes a shown page at once
and marks a hidden one dirty, so a result arriving while the user is on page 2 does not redraw
the charts, 3D view and depth preview of pages 4-7 on the GUI thread.
"""

from __future__ import annotations

from pathlib import Path
from typing import Protocol

import numpy as np
from PySide6.QtWidgets import QWidget

from ...models.calibration import Key, WizardModel


class WizardActions(Protocol):
    """What pages may ask the wizard to do (implemented by :class:`~.wizard.CalibrationWizard`)."""

    busy_changed: object  # Signal(bool)
    last_error: str | None

    def is_busy(self) -> bool: ...
    def open_session(self, path: str | Path, resume: bool = True) -> bool: ...
    def set_session(self, session) -> None: ...
    def run_detection(self, keys: set[Key] | None = None) -> None: ...
    def redetect(self, key: Key, options) -> None: ...
    def set_detector(self, detector: str) -> None: ...
    def recalibrate(self) -> None: ...
    def show_view(self, camera: str, pose: str) -> None: ...
    def save_outputs(self, rig_path: Path, report_path: Path | None, roi_min: np.ndarray,
                     roi_max: np.ndarray) -> None: ...


class WizardPage(QWidget):
    """Base of the seven pages: ``model`` + ``actions``; lazy refresh while hidden."""

    title = ""

    def __init__(self, model: WizardModel, actions: WizardActions) -> None:
        super().__init__()
        self.model = model
        self.actions = actions
        self._dirty = True

    def refresh(self) -> None:
        """Redraw from the model (override)."""

    def refresh_later(self, *_args) -> None:
        """Refresh now if shown, else when next shown."""
        if self.isVisible():
            self._dirty = False
            self.refresh()
        else:
            self._dirty = True

    def leave(self) -> bool:
        """Called before 'Next' leaves the page; False keeps the user here (override)."""
        return True

    def showEvent(self, event) -> None:  # noqa: N802
        super().showEvent(event)
        if self._dirty:
            self._dirty = False
            self.refresh()
