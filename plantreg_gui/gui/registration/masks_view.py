"""Mask overlays: a source camera's case map and the target's area map over a registered image,
each toggleable (per code too), with opacity and a legend in the paper's colours with counts."""

from __future__ import annotations

import cv2
import numpy as np
from PySide6.QtCore import Qt, Signal
from PySide6.QtGui import QBrush, QColor
from PySide6.QtWidgets import (
    QAbstractItemView, QCheckBox, QComboBox, QFormLayout, QFrame, QGroupBox, QHBoxLayout, QHeaderView, QLabel,
    QScrollArea, QSlider, QSplitter, QTableWidget, QTableWidgetItem, QVBoxLayout, QWidget,
)

from ...core.display import display
from ...core.registration.cases import AREA_NAMES, CASE_NAMES
from .image_views import ImageView
from ...models.layers import case_table


#: overlay colours of the other masks: red mixed edge pixels, blue flying pixels
EXTRA_COLOURS = {"mixed edge pixels": (255, 40, 40), "flying pixels": (60, 120, 255)}


class Legend(QTableWidget):
    """Rows: [x] colour  name | count | %. Unchecking a row hides that code's overlay."""

    changed = Signal()

    def __init__(self, parent: QWidget | None = None):
        super().__init__(0, 3, parent)
        self.setHorizontalHeaderLabels(["class", "pixels", "%"])
        self.verticalHeader().setVisible(False)
        self.setEditTriggers(QAbstractItemView.EditTrigger.NoEditTriggers)
        self.setSelectionMode(QAbstractItemView.SelectionMode.NoSelection)
        hh = self.horizontalHeader()
        hh.setSectionResizeMode(0, QHeaderView.ResizeMode.Stretch)
        hh.setSectionResizeMode(1, QHeaderView.ResizeMode.ResizeToContents)
        hh.setSectionResizeMode(2, QHeaderView.ResizeMode.ResizeToContents)
        self.codes: list[int] = []
        self.counts: dict[int, int] = {}
        self.itemChanged.connect(lambda _i: self.changed.emit())

    def set_rows(self, rows: list[tuple[int, str, object, int, float]]) -> None:
        enabled = self.enabled_codes() if self.codes else None
        self.blockSignals(True)
        self.setRowCount(len(rows))
        self.codes = [r[0] for r in rows]
        self.counts = {r[0]: r[3] for r in rows}
        for i, (code, name, rgb, count, pct) in enumerate(rows):
            it = QTableWidgetItem(name)
            it.setFlags(Qt.ItemFlag.ItemIsEnabled | Qt.ItemFlag.ItemIsUserCheckable)
            on = rgb is not None and (enabled is None or code in enabled)
            it.setCheckState(Qt.CheckState.Checked if on else Qt.CheckState.Unchecked)
            if rgb is not None:
                it.setData(Qt.ItemDataRole.DecorationRole, QColor(*rgb))
            else:
                it.setFlags(Qt.ItemFlag.ItemIsEnabled)
                it.setForeground(QBrush(QColor(110, 110, 110)))
                it.setToolTip("no overlay (as in the paper)")
            self.setItem(i, 0, it)
            c = QTableWidgetItem(f"{count:,}")
            c.setTextAlignment(Qt.AlignmentFlag.AlignRight | Qt.AlignmentFlag.AlignVCenter)
            self.setItem(i, 1, c)
            p = QTableWidgetItem(f"{pct:.1f}")
            p.setTextAlignment(Qt.AlignmentFlag.AlignRight | Qt.AlignmentFlag.AlignVCenter)
            self.setItem(i, 2, p)
        self.blockSignals(False)
        self.resizeRowsToContents()
        h = self.horizontalHeader().height() + sum(self.rowHeight(i) for i in range(self.rowCount())) + 4
        self.setFixedHeight(h)

    def set_swatches(self, shown: dict[int, tuple[int, int, int]], opacity: float) -> None:
        """Swatches in the colour each code shows as on the map (``shown``; codes absent keep theirs)."""
        self.blockSignals(True)
        for i, code in enumerate(self.codes):
            it = self.item(i, 0)
            if it is not None and code in shown:
                it.setData(Qt.ItemDataRole.DecorationRole, QColor(*shown[code]))
                it.setToolTip(f"the colour as it shows on the map ({100 * opacity:.0f} % over the image)")
        self.blockSignals(False)

    def enabled_codes(self) -> set[int]:
        return {c for i, c in enumerate(self.codes)
                if self.item(i, 0) is not None and self.item(i, 0).checkState() == Qt.CheckState.Checked}


class MasksView(QWidget):
    hovered = Signal(str, int, int)

    def __init__(self, parent: QWidget | None = None):
        super().__init__(parent)
        self.renders: dict[str, np.ndarray] = {}
        self.cases: dict[str, np.ndarray] = {}
        self.area: np.ndarray | None = None
        self.target = ""
        self.view = ImageView("masks")
        self.view.hovered.connect(lambda r, c: self.hovered.emit("masks", r, c))

        self.base = QComboBox()
        self.base.setToolTip("the registered image under the overlays")
        self.source = QComboBox()
        self.source.setToolTip("the source camera whose case map is shown")
        self.show_cases = QCheckBox("Case map (per source)")
        self.show_cases.setChecked(True)
        self.show_areas = QCheckBox("Area map (target)")
        self.opacity = QSlider(Qt.Orientation.Horizontal)
        self.opacity.setRange(0, 100)
        self.opacity.setValue(60)
        self.case_legend = Legend()
        self.area_legend = Legend()

        form = QFormLayout()
        form.addRow("Image", self.base)
        form.addRow("Source", self.source)
        form.addRow("Opacity", self.opacity)
        g1 = QGroupBox("Projection cases of the source")
        l1 = QVBoxLayout(g1)
        l1.addWidget(self.show_cases)
        l1.addWidget(self.case_legend)
        g2 = QGroupBox("Target areas")
        l2 = QVBoxLayout(g2)
        l2.addWidget(self.show_areas)
        l2.addWidget(self.area_legend)
        self.extra_box = QGroupBox("Other masks")
        self.extra_layout = QVBoxLayout(self.extra_box)
        self.extra: dict[str, tuple[QCheckBox, np.ndarray]] = {}
        self.extra_box.hide()
        self.note = QLabel("Rows without a colour have no overlay (P1, P6), as in the paper. P2: occluded in the "
                           "source; P3.1/P3.2: the depth camera cannot see there; %: of all target pixels.")
        self.note.setWordWrap(True)
        self.note.setStyleSheet("color: #555; font-size: 11px;")
        side = QWidget()
        sl = QVBoxLayout(side)
        sl.setContentsMargins(4, 0, 4, 0)
        sl.addLayout(form)
        sl.addWidget(g1)
        sl.addWidget(g2)
        sl.addWidget(self.extra_box)
        sl.addWidget(self.note)
        sl.addStretch(1)
        side.setMinimumWidth(290)
        # the legends scroll on a short window instead of making the window taller than a laptop's
        side_scroll = QScrollArea()
        side_scroll.setWidget(side)
        side_scroll.setWidgetResizable(True)
        side_scroll.setFrameShape(QFrame.Shape.NoFrame)
        side_scroll.setHorizontalScrollBarPolicy(Qt.ScrollBarPolicy.ScrollBarAlwaysOff)
        side_scroll.setMinimumWidth(300)
        side_scroll.setMaximumWidth(420)

        split = QSplitter(Qt.Orientation.Horizontal)
        split.addWidget(self.view)
        split.addWidget(side_scroll)
        split.setStretchFactor(0, 1)
        split.setStretchFactor(1, 0)
        split.setChildrenCollapsible(False)
        lay = QHBoxLayout(self)
        lay.setContentsMargins(2, 2, 2, 2)
        lay.addWidget(split)

        self.session = None
        self.source.currentIndexChanged.connect(self._source_changed)
        for w in (self.base,):
            w.currentIndexChanged.connect(self.update_view)
        for w in (self.show_cases, self.show_areas):
            w.toggled.connect(self.update_view)
        self.opacity.valueChanged.connect(self.update_view)
        self.case_legend.changed.connect(self.update_view)
        self.area_legend.changed.connect(self.update_view)

    def set_data(self, target: str, renders: dict[str, np.ndarray], order: list[str],
                 cases: dict[str, np.ndarray], area: np.ndarray, source: str | None = None) -> None:
        """``renders`` display renderings in the target grid; ``cases[source]`` (H, W) uint8 case
        codes; ``area`` (H, W) uint8 area codes; ``source`` the case map to show."""
        self.target, self.renders, self.cases, self.area = target, renders, cases, area
        for combo, items, keep in ((self.base, [n for n in order if n in renders], self.base.currentText()),
                                   (self.source, list(cases), source or self.source.currentText())):
            combo.blockSignals(True)
            combo.clear()
            combo.addItems(items)
            if keep in items:
                combo.setCurrentText(keep)
            combo.blockSignals(False)
        self.area_legend.set_rows(case_table(area, AREA_NAMES, display.AREA_COLOURS))
        self._show_source()

    def set_source(self, name: str) -> None:
        self.source.setCurrentText(name)

    def _source_changed(self) -> None:
        if self.session is not None:
            self.session.set_masks_source(self.source.currentText())  # comes back as masks_source
        else:
            self._show_source()

    def _show_source(self) -> None:
        src = self.source.currentText()
        if src in self.cases:
            self.case_legend.set_rows(case_table(self.cases[src], CASE_NAMES, display.CASE_COLOURS))
        self.update_view()

    def showEvent(self, e) -> None:  # noqa: N802
        super().showEvent(e)
        if getattr(self, "_stale", False):
            self.update_view()

    # ------------------------------------------------------------------ the workspace's session
    needs = "result"

    def bind(self, session) -> "MasksView":
        """Show ``session``'s case and area maps over its renderings; the source is the session's."""
        from .image_views import home_rect

        self.session = session

        def refresh() -> None:
            r = session.result
            self.view.set_home(home_rect(session.home))
            if r is None:
                self.set_data("", {}, [], {}, np.zeros((0, 0), np.uint8))
                self.view.clear()
                return
            self.set_data(r.target, session.renders, [L.name for L in session.layers], r.cases, r.area,
                          session.masks_source)

        def source() -> None:
            if session.masks_source and self.source.currentText() != session.masks_source:
                self.source.blockSignals(True)
                self.source.setCurrentText(session.masks_source)
                self.source.blockSignals(False)
            self._show_source()

        session.events.result.connect(refresh)
        session.events.masks_source.connect(source)
        session.events.masks_source.connect(lambda: self.set_extra_masks(session.mask_layers()))
        session.events.result.connect(lambda: self.set_extra_masks(session.mask_layers()))
        session.events.display.connect(lambda _name: self.update_view())
        self.hovered.connect(lambda _src, r, c: session.hover("target", r, c))
        return self

    def composite(self) -> np.ndarray | None:
        base = self.renders.get(self.base.currentText())
        if base is None:
            return None
        op = self.opacity.value() / 100.0
        # the base is dimmed to grey so the overlay colours read clearly (OpenCV: a float mean of a
        # 4K picture stalls the GUI thread)
        out = cv2.cvtColor(cv2.cvtColor(np.ascontiguousarray(base), cv2.COLOR_RGB2GRAY), cv2.COLOR_GRAY2RGB)
        if self.show_areas.isChecked() and self.area is not None:
            on = self.area_legend.enabled_codes()
            out = display.overlay(out, self.area, {c: v for c, v in display.AREA_COLOURS.items() if c in on}, op)
        src = self.source.currentText()
        if self.show_cases.isChecked() and src in self.cases:
            on = self.case_legend.enabled_codes()
            out = display.overlay(out, self.cases[src], {c: v for c, v in display.CASE_COLOURS.items() if c in on}, op)
            self.case_legend.set_swatches(display.shown_colours(out, self.cases[src], on & set(display.CASE_COLOURS)), op)
        if self.show_areas.isChecked() and self.area is not None:
            on = self.area_legend.enabled_codes()
            self.area_legend.set_swatches(display.shown_colours(out, self.area, on & set(display.AREA_COLOURS)), op)
        for name, (cb, mask) in self.extra.items():
            if cb.isChecked() and mask.shape == out.shape[:2]:
                out = display.overlay(out, mask.astype(np.uint8), {1: EXTRA_COLOURS.get(name, (255, 0, 0))}, op)
        return out

    def set_extra_masks(self, masks: list[tuple[str, np.ndarray, str]]) -> None:
        """Boolean masks offered as overlays (mixed edge pixels, flying pixels), with their meaning."""
        keep = {n for n, (cb, _m) in self.extra.items() if cb.isChecked()}
        for cb, _m in self.extra.values():
            self.extra_layout.removeWidget(cb)
            cb.deleteLater()
        self.extra = {}
        for name, mask, what in masks:
            cb = QCheckBox(f"{name} ({int(mask.sum()):,})")
            cb.setToolTip(what)
            cb.setChecked(name in keep)
            cb.toggled.connect(self.update_view)
            self.extra_layout.addWidget(cb)
            self.extra[name] = (cb, mask)
        self.extra_box.setVisible(bool(masks))

    def update_view(self) -> None:
        if not self.isVisible():  # composed when shown (showEvent): hidden tabs cost nothing
            self._stale = True
            return
        self._stale = False
        img = self.composite()
        if img is None:
            self.view.clear()
        else:
            self.view.set_rgb8(img)
