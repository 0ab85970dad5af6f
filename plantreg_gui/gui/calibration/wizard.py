"""Calibration wizard (placeholder until its issue lands)."""

from PySide6.QtCore import Signal
from PySide6.QtWidgets import QLabel, QVBoxLayout, QWidget


class CalibrationWizard(QWidget):
    idle = Signal()

    def __init__(self, parent=None):
        super().__init__(parent)
        QVBoxLayout(self).addWidget(QLabel("Calibration wizard"))

    def is_busy(self) -> bool:
        return False

    def shutdown(self) -> None:
        pass
