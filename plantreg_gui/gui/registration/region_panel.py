"""The region tool's panel: choose rectangle or polygon, draw it on the registered images (Side by
side), read the chosen source's statistics over it, export them as CSV.

The statistics are computed by the core (:mod:`plantreg_gui.core.registration.region`) through the session;
this panel only shows ``session.region_stats`` and asks for a file name.
"""

from __future__ import annotations

import numpy as np
from PySide6.QtCore import Qt, Signal
from PySide6.QtWidgets import (
    QButtonGroup, QComboBox, QGroupBox, QHBoxLayout, QLabel, QPushButton, QVBoxLayout, QWidget,
)

from .image_views import SpectrumPlot
from ...models.layers import format_value


class RegionPanel(QGroupBox):
    """``tool_changed(mode)``: "rect", "polygon" or None (the workspace sets the views' draw mode)."""

    tool_changed = Signal(object)

    def __init__(self, session, parent: QWidget | None = None):
        super().__init__("Region", parent)
        self.session = session
        self.rect_button = QPushButton("Rectangle")
        self.poly_button = QPushButton("Polygon")
        self.rect_button.setToolTip("drag a rectangle on a registered image (Side by side)")
        self.poly_button.setToolTip("click the corners on a registered image; double-click closes the polygon")
        self.group = QButtonGroup(self)
        self.group.setExclusive(False)
        for b in (self.rect_button, self.poly_button):
            b.setCheckable(True)
            self.group.addButton(b)
        self.clear_button = QPushButton("Clear")
        self.csv_button = QPushButton("CSV…")
        self.csv_button.setToolTip("save every camera's statistics over the region as CSV")
        self.source = QComboBox()
        self.source.setToolTip("the camera whose values and cases are summarised (also the Masks view's source)")
        row = QHBoxLayout()
        for w in (self.rect_button, self.poly_button, self.clear_button, self.csv_button):
            row.addWidget(w)
        srow = QHBoxLayout()
        srow.addWidget(QLabel("Source"))
        srow.addWidget(self.source, 1)
        self.text = QLabel("")
        self.text.setWordWrap(True)
        self.text.setTextInteractionFlags(Qt.TextInteractionFlag.TextSelectableByMouse)
        self.text.setStyleSheet("font-size: 11px;")
        self.spectrum = SpectrumPlot()
        self.spectrum.hide()
        lay = QVBoxLayout(self)
        lay.setContentsMargins(6, 4, 6, 4)
        lay.addLayout(row)
        lay.addLayout(srow)
        lay.addWidget(self.text)
        lay.addWidget(self.spectrum)

        self.rect_button.toggled.connect(lambda on: self._tool("rect", on))
        self.poly_button.toggled.connect(lambda on: self._tool("polygon", on))
        self.clear_button.clicked.connect(lambda: session.set_region(None))
        # csv_button: the owner (the workspace) asks for the file and computes on a worker
        self.source.currentTextChanged.connect(self._source_chosen)
        session.events.result.connect(self._result)
        session.events.masks_source.connect(self._masks_source)
        session.events.region.connect(self._show)
        self._result()

    # ------------------------------------------------------------------ tool
    def _tool(self, mode: str, on: bool) -> None:
        other = self.poly_button if mode == "rect" else self.rect_button
        if on and other.isChecked():
            other.blockSignals(True)
            other.setChecked(False)
            other.blockSignals(False)
        self.tool_changed.emit(mode if on else None)

    def set_tool(self, mode: str | None) -> None:
        """Choose the drawing tool as the buttons do ("rect", "polygon", None)."""
        (self.rect_button if mode == "rect" else self.poly_button).setChecked(mode is not None)
        if mode is None:
            self.rect_button.setChecked(False)

    # ------------------------------------------------------------------ session -> panel
    def _result(self) -> None:
        s = self.session
        r = s.result
        self.setEnabled(r is not None)
        self.source.blockSignals(True)
        self.source.clear()
        if r is not None:
            self.source.addItems(list(r.cases))  # sources have cases; the masks source is one of them
            self.source.setCurrentText(s.masks_source or "")
        self.source.blockSignals(False)
        if r is None:
            self.set_tool(None)
        self._show()

    def _masks_source(self) -> None:
        if self.session.masks_source and self.source.currentText() != self.session.masks_source:
            self.source.blockSignals(True)
            self.source.setCurrentText(self.session.masks_source)
            self.source.blockSignals(False)

    def _source_chosen(self, name: str) -> None:
        if name:
            self.session.set_masks_source(name)

    def _show(self) -> None:
        s = self.session
        st = s.region_stats
        self.csv_button.setEnabled(st is not None)
        self.clear_button.setEnabled(s.region is not None)
        if st is None:
            hint = ("Choose Rectangle or Polygon and draw on a registered image: the chosen source's "
                    "cases and values over the region appear here.")
            self.text.setText("" if s.result is None else "Computing the statistics…" if s.region is not None else
                              f"{s.region_note} {hint}" if s.region_note else hint)
            self.spectrum.hide()
            return
        cases = "  ".join(f"{k} {n:,} ({p:.1f}%)" for k, (n, p) in st.cases.items() if n)
        lines = [f"<b>{st.source}</b> over {st.pixels:,} px", cases,
                 f"P1 not mixed: {st.trusted:,} px" + (f" ({st.mixed:,} mixed left out)" if st.mixed else "")]
        L = s.layer(st.source)
        mod, unit = (L.modality, L.unit) if L is not None else ("", None)
        if st.bands == 1:
            if np.isfinite(st.mean[0]):
                lines.append(f"mean <b>{format_value(st.mean[0], mod, unit)}</b>, "
                             f"median {format_value(st.median[0], mod, unit)}, std {format_value(st.std[0], mod, unit)}")
            else:
                lines.append("no P1 value in the region")
            self.spectrum.hide()
        else:
            lines.append(f"mean spectrum of {st.bands} bands below" if st.trusted else "no P1 value in the region")
            self.spectrum.show()
            self.spectrum.set_spectrum(st.mean if st.trusted else None, st.wavelengths,
                                       f"{st.source}: mean over {st.trusted:,} P1 px")
        self.text.setText("<br>".join(lines))
