"""Export dialog: choose a folder, the parts to write and whether mixed pixels are dropped; the
workspace runs the pipeline's export (:func:`plantreg_gui.core.pipeline.pipeline.export`) on a worker."""

from __future__ import annotations

from pathlib import Path

from PySide6.QtWidgets import (
    QCheckBox, QDialog, QDialogButtonBox, QFileDialog, QGroupBox, QHBoxLayout, QLabel, QLineEdit,
    QPushButton, QVBoxLayout, QWidget,
)

def parts() -> dict[str, str]:
    """Output part -> label shown to the user, from the core's one registry (core.export.OUTPUT_PARTS)."""
    from ...core.export.export import OUTPUT_PARTS  # on demand: the export module pulls in the registration engine

    return {p.key: p.label for p in OUTPUT_PARTS}


def folder_is_nonempty(path: str | Path) -> bool:
    p = Path(path)
    return p.exists() and (not p.is_dir() or any(p.iterdir()))


class ExportDialog(QDialog):
    def __init__(self, folder: str | Path = "", parent: QWidget | None = None):
        super().__init__(parent)
        self.setWindowTitle("Export registration")
        self.folder = QLineEdit(str(folder))
        self.folder.setMinimumWidth(420)
        browse = QPushButton("Browse…")
        browse.clicked.connect(self._browse)
        row = QHBoxLayout()
        row.addWidget(QLabel("Folder"))
        row.addWidget(self.folder, 1)
        row.addWidget(browse)
        box = QGroupBox("Write")
        bl = QVBoxLayout(box)
        self.boxes: dict[str, QCheckBox] = {}
        for key, label in parts().items():
            cb = QCheckBox(label)
            cb.setChecked(True)
            self.boxes[key] = cb
            bl.addWidget(cb)
        self.drop = QCheckBox("Drop mixed pixels (NaN where a pixel's footprint crosses a silhouette)")
        self.drop.setToolTip("as plantreg register --drop-mixed: the registered images get NaN where a "
                             "pixel is flagged mixed; the view here keeps its values")
        note = QLabel("The folder is written under a temporary name and moved into place when complete. "
                      "An existing, non-empty folder is replaced only after you confirm.")
        note.setWordWrap(True)
        note.setStyleSheet("color: #555;")
        self.buttons = QDialogButtonBox(QDialogButtonBox.StandardButton.Ok | QDialogButtonBox.StandardButton.Cancel)
        self.buttons.button(QDialogButtonBox.StandardButton.Ok).setText("Export")
        self.buttons.accepted.connect(self.accept)
        self.buttons.rejected.connect(self.reject)
        lay = QVBoxLayout(self)
        lay.addLayout(row)
        lay.addWidget(box)
        lay.addWidget(self.drop)
        lay.addWidget(note)
        lay.addWidget(self.buttons)
        # Export only with a folder and at least one part: an empty field would mean the current
        # directory (and "replace it?"), nothing ticked would write an empty folder
        self.folder.textChanged.connect(self._validate)
        for cb in self.boxes.values():
            cb.toggled.connect(self._validate)
        self._validate()

    def _validate(self) -> None:
        ok_btn = self.buttons.button(QDialogButtonBox.StandardButton.Ok)
        if not self.folder.text().strip():
            ok_btn.setEnabled(False)
            ok_btn.setToolTip("choose the folder to export to")
        elif not self.what():
            ok_btn.setEnabled(False)
            ok_btn.setToolTip("tick at least one part to write")
        else:
            ok_btn.setEnabled(True)
            ok_btn.setToolTip("")

    def _browse(self) -> None:
        d = QFileDialog.getExistingDirectory(self, "Export folder", self.folder.text() or str(Path.home()))
        if d:
            self.folder.setText(d)

    def out(self) -> Path:
        return Path(self.folder.text().strip()).expanduser()

    def what(self) -> list[str]:
        return [k for k, cb in self.boxes.items() if cb.isChecked()]

    def drop_mixed(self) -> bool:
        return self.drop.isChecked()
