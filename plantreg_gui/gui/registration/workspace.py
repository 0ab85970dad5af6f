"""Registration workspace (placeholder until its issue lands)."""

from PySide6.QtCore import Signal
from PySide6.QtWidgets import QLabel, QVBoxLayout, QWidget


class RegistrationWorkspace(QWidget):
    idle = Signal()

    def __init__(self, parent=None):
        super().__init__(parent)
        QVBoxLayout(self).addWidget(QLabel("Registration workspace"))

    def is_busy(self) -> bool:
        return False

    def shutdown(self) -> None:
        pass
