"""Help ▸ About: plantreg's and its libraries' versions and the files the window has open, as
selectable text (to paste into a bug report). Imports nothing heavy: versions of libraries not
yet loaded come from their installed metadata (``plantreg_gui/versions.py``)."""

from __future__ import annotations

import html
from pathlib import Path

from PySide6.QtCore import QSettings, Qt, qVersion
from PySide6.QtGui import QGuiApplication
from PySide6.QtWidgets import QDialog, QDialogButtonBox, QLabel, QVBoxLayout

from .. import __version__
from ..versions import versions


def about_rows(paths: list[tuple[str, Path | str | None]]) -> list[tuple[str, str]]:
    """[(label, text)] the dialog shows: versions (Qt's run-time version beside PySide6's), then
    ``paths`` (None: "none open"), where plantreg is installed and its settings file."""
    rows = []
    for label, v in versions():
        rows.append((label, v))
        if label == "PySide6":
            rows.append(("Qt", qVersion()))
    for label, p in paths:
        rows.append((label, str(p) if p else "none open"))
    rows.append(("installed in", str(Path(__file__).resolve().parents[1])))
    rows.append(("settings", QSettings("plantreg", "plantreg").fileName()))
    return rows


class AboutDialog(QDialog):
    def __init__(self, parent=None, paths: list[tuple[str, Path | str | None]] | None = None) -> None:
        super().__init__(parent)
        self.setWindowTitle("About plantreg")
        self.rows = about_rows(paths or [])
        lay = QVBoxLayout(self)
        head = QLabel(f"<h3>plantreg {html.escape(__version__)}</h3>"
                      "Multimodal 3D image registration for plant phenotyping rigs "
                      "(after Stumpe et al.). MIT licence.")
        head.setWordWrap(True)
        lay.addWidget(head)
        table = "".join(f"<tr><td style='padding-right:12px'><b>{html.escape(k)}</b></td>"
                        f"<td>{html.escape(v)}</td></tr>" for k, v in self.rows)
        self.text = QLabel(f"<table>{table}</table>")
        self.text.setTextFormat(Qt.TextFormat.RichText)
        self.text.setTextInteractionFlags(Qt.TextInteractionFlag.TextSelectableByMouse)
        lay.addWidget(self.text)
        buttons = QDialogButtonBox(QDialogButtonBox.StandardButton.Close)
        copy = buttons.addButton("Copy", QDialogButtonBox.ButtonRole.ActionRole)
        copy.setToolTip("copy these lines to the clipboard (for a bug report)")
        copy.clicked.connect(lambda: QGuiApplication.clipboard().setText(self.plain_text()))
        buttons.rejected.connect(self.reject)
        lay.addWidget(buttons)

    def plain_text(self) -> str:
        return "\n".join(f"{k}: {v}" for k, v in self.rows)
