"""Per-modality display controls: colour map, contrast limits by percentile or absolute (in the
image's unit, optionally locked across recordings), and for cubes PCA false colour or three
chosen bands (picked in nm when the rig gives the band centres). Emits the new settings; the
workspace re-renders."""

from __future__ import annotations

from PySide6.QtCore import QTimer, Signal
from PySide6.QtWidgets import (
    QCheckBox, QComboBox, QDoubleSpinBox, QFormLayout, QGroupBox, QHBoxLayout, QLabel, QSpinBox, QVBoxLayout,
    QWidget,
)

import numpy as np

from ...core.display import display
from ...core.camera import modality
from ...models.layers import COLORMAPS, DisplaySettings, Layer


class BandSpinBox(QSpinBox):
    """A band index shown as its centre wavelength ("552 nm") when the cube's ``wavelengths`` are
    known (the rig's ``bands`` metadata), else as the index; typing a wavelength picks the nearest band."""

    def __init__(self, parent: QWidget | None = None):
        super().__init__(parent)
        self.wavelengths: np.ndarray | None = None

    def set_wavelengths(self, wl: np.ndarray | None) -> None:
        self.wavelengths = None if wl is None else np.asarray(wl, np.float64).ravel()
        self.setToolTip("band centre (nm)" if self.wavelengths is not None else "band index (the rig gives no "
                        "wavelengths: add the camera's \"bands\" in nm to show them here)")
        self.lineEdit().setText(self.textFromValue(self.value()))

    def textFromValue(self, v: int) -> str:  # noqa: N802 (Qt name)
        wl = self.wavelengths
        if wl is not None and 0 <= v < wl.size:
            return f"{wl[v]:.0f} nm"
        return str(v)

    def valueFromText(self, text: str) -> int:  # noqa: N802
        t = text.replace("nm", "").strip()
        try:
            x = float(t)
        except ValueError:
            return self.value()
        wl = self.wavelengths
        if wl is not None:
            return int(np.argmin(np.abs(wl - x)))
        return int(round(x))

    def validate(self, text: str, pos: int):  # noqa: D401 - any text; valueFromText decides
        from PySide6.QtGui import QValidator

        return QValidator.State.Intermediate if not text.strip() else QValidator.State.Acceptable, text, pos


class Histogram(QWidget):
    """The value histogram of the shown single-band layer with the colour limits marked (as
    napari's and ImageJ's contrast dialogs): where the limits cut the data, at a glance.
    ``counts`` (bins,), ``edges`` (bins + 1,) and ``limits`` (lo, hi) in the layer's unit."""

    def __init__(self, parent: QWidget | None = None):
        super().__init__(parent)
        self.counts: np.ndarray | None = None
        self.edges: np.ndarray | None = None
        self.limits: tuple[float, float] | None = None
        self.setFixedHeight(46)
        self.setMinimumWidth(60)

    def set_data(self, hist: tuple[np.ndarray, np.ndarray] | None, limits: tuple[float, float] | None,
                 unit: str = "") -> None:
        self.counts, self.edges = (None, None) if hist is None else hist
        self.limits = limits
        self.setVisible(hist is not None)
        if hist is not None and limits is not None:
            inside = float(self.counts[(self.edges[:-1] >= limits[0]) & (self.edges[1:] <= limits[1])].sum())
            self.setToolTip(f"values {self.edges[0]:.4g}-{self.edges[-1]:.4g} {unit}; limits "
                            f"{limits[0]:.4g}-{limits[1]:.4g} {unit} (red); "
                            f"{100 * inside / max(float(self.counts.sum()), 1):.0f} % of the pixels between them. "
                            "Bar heights: log of the pixel count (a tail of 1 % shows)")
        self.update()

    def x_of(self, v: float) -> float:
        """Widget x of value ``v``."""
        lo, hi = float(self.edges[0]), float(self.edges[-1])
        return (v - lo) / (hi - lo if hi > lo else 1.0) * (self.width() - 1)

    def paintEvent(self, _e) -> None:  # noqa: N802 (Qt name)
        from PySide6.QtGui import QColor, QPainter

        if self.counts is None:
            return
        p = QPainter(self)
        w, h = self.width(), self.height()
        p.fillRect(0, 0, w, h, QColor("#f4f4f4"))
        c = np.log1p(self.counts.astype(np.float64))  # log: a dark background would flatten the rest
        c = c / (c.max() or 1.0)
        n = len(c)
        p.setPen(QColor("#777"))
        for i, v in enumerate(c):
            x0, x1 = int(i * w / n), max(int((i + 1) * w / n) - 1, int(i * w / n))
            p.fillRect(x0, int(h - v * (h - 2)), x1 - x0 + 1, int(v * (h - 2)), QColor("#8a8f98"))
        f = p.font()
        f.setPointSizeF(max(f.pointSizeF() * 0.75, 6.0))
        p.setFont(f)
        fm = p.fontMetrics()
        label = "log count"  # said on the widget, not only in its tip
        p.fillRect(1, 1, fm.horizontalAdvance(label) + 4, fm.height(), QColor(244, 244, 244, 220))
        p.setPen(QColor("#444"))
        p.drawText(3, fm.ascent() + 1, label)
        if self.limits is not None:
            p.setPen(QColor("#c00000"))
            for v in self.limits:
                x = int(round(min(max(self.x_of(v), 0), w - 1)))
                p.drawLine(x, 0, x, h)
        p.end()


class DisplayControls(QGroupBox):
    """``changed(name, settings)`` after the user edits a modality's settings (throttled 80 ms)."""

    changed = Signal(str, object)

    def __init__(self, parent: QWidget | None = None):
        super().__init__("Display", parent)
        self.settings: dict[str, DisplaySettings] = {}
        self.layers: dict[str, Layer] = {}
        self.layer = QComboBox()
        self.cmap = QComboBox()
        self.cmap.addItem("default", None)
        for c in COLORMAPS:
            self.cmap.addItem(c, c)
        self.lo = QDoubleSpinBox()
        self.hi = QDoubleSpinBox()
        for sb, v in ((self.lo, 1.0), (self.hi, 99.0)):
            sb.setKeyboardTracking(False)
            sb.setValue(v)
        self.limit_mode = QComboBox()
        self.limit_mode.addItem("percentiles", "percentiles")
        self.limit_mode.addItem("absolute", "absolute")
        self.limit_mode.setToolTip("percentiles of each image's values, or absolute values in the image's unit")
        self.lock = QCheckBox("Lock limits across recordings")
        self.lock.setToolTip("keep these absolute limits when another recording is opened (and next time), so "
                             "colours mean the same values in every recording")
        self._set_limit_kind("percentiles")
        self.mode = QComboBox()
        self.mode.addItem("PCA false colour", "pca")
        self.mode.addItem("three bands (R, G, B)", "bands")
        self.bands = [BandSpinBox() for _ in range(3)]
        bl = QHBoxLayout()
        for sb in self.bands:
            sb.setRange(0, 0)
            bl.addWidget(sb)
        self.band_row = QWidget()
        self.band_row.setLayout(bl)
        bl.setContentsMargins(0, 0, 0, 0)
        self.info = QLabel("")
        self.info.setWordWrap(True)
        self.info.setStyleSheet("color: #555; font-size: 11px;")

        form = QFormLayout()
        form.addRow("Modality", self.layer)
        form.addRow("Colour map", self.cmap)
        lim = QHBoxLayout()
        lim.addWidget(self.lo)
        lim.addWidget(QLabel("–"))
        lim.addWidget(self.hi)
        form.addRow("Limits", self.limit_mode)
        form.addRow("", lim)
        form.addRow("", self.lock)
        self.histogram = Histogram()
        form.addRow("", self.histogram)
        self.limits_note = QLabel("Lower limit must be below the upper; not applied.")
        self.limits_note.setStyleSheet("color: #a00000; font-size: 11px;")
        self.limits_note.setWordWrap(True)  # wrapped, never cut ("…not ap") by the side panel's width
        self.limits_note.hide()
        form.addRow("", self.limits_note)
        form.addRow("Cube as", self.mode)
        form.addRow("Bands", self.band_row)
        lay = QVBoxLayout(self)
        lay.addLayout(form)
        lay.addWidget(self.info)

        self._timer = QTimer(self)
        self._timer.setSingleShot(True)
        self._timer.setInterval(80)
        self._timer.timeout.connect(self._emit)
        self.layer.currentIndexChanged.connect(self._show_layer)
        for w in (self.cmap, self.mode):
            w.currentIndexChanged.connect(self._edited)
        self.limit_mode.currentIndexChanged.connect(self._limit_kind_changed)
        self.lock.toggled.connect(self._edited)
        for sb in (self.lo, self.hi, *self.bands):
            sb.valueChanged.connect(self._edited)
        self._loading = False
        self.setEnabled(False)

    # ------------------------------------------------------------------ state
    def set_layers(self, layers: list[Layer]) -> None:
        self.layers = {L.name: L for L in layers}
        for L in layers:
            self.settings.setdefault(L.name, DisplaySettings())
        keep = self.layer.currentText()
        self.layer.blockSignals(True)
        self.layer.clear()
        self.layer.addItems([L.name for L in layers])
        if keep in self.layers:
            self.layer.setCurrentText(keep)
        self.layer.blockSignals(False)
        self.setEnabled(bool(layers))
        if not layers:  # closed: nothing of the last recording stays on show
            self.histogram.set_data(None, None)
            self.info.setText("")
            self.limits_note.hide()
        self._show_layer()

    def settings_for(self, name: str) -> DisplaySettings:
        return self.settings.get(name, DisplaySettings())

    def _show_layer(self) -> None:
        L = self.layers.get(self.layer.currentText())
        if L is None:
            return
        s = self.settings_for(L.name)
        self._loading = True
        is_cube = L.is_cube
        single = L.bands == 1
        self.cmap.setEnabled(single)
        i = self.cmap.findData(s.cmap) if s.cmap else 0
        self.cmap.setCurrentIndex(max(i, 0))
        self.limit_mode.setCurrentIndex(1 if s.limits is not None else 0)
        self._set_limit_kind("absolute" if s.limits is not None else "percentiles", L.unit)
        lo, hi = s.limits if s.limits is not None else s.percentiles
        self.lo.setValue(lo)
        self.hi.setValue(hi)
        self.lock.setChecked(s.locked)
        self.lock.setEnabled(s.limits is not None)
        self.mode.setEnabled(is_cube)
        # what "no bands chosen" draws: a 3-band cube is RGB (core.display.shows_as_rgb), not PCA
        self.mode.setItemText(0, "RGB (as recorded)" if display.shows_as_rgb(L.bands, L.modality)
                              else "PCA false colour")
        self.mode.setCurrentIndex(1 if s.bands is not None else 0)
        for k, sb in enumerate(self.bands):
            sb.setRange(0, max(L.bands - 1, 0))
            sb.set_wavelengths(L.wavelengths if is_cube else None)
            default = (0, L.bands // 2, L.bands - 1)[k] if is_cube else 0
            sb.setValue(s.bands[k] if s.bands is not None else default)
        self.band_row.setEnabled(is_cube and s.bands is not None)
        default_cmap = modality.default_cmap(L.modality)
        unit = f", {L.unit}" if L.unit else ""
        kind = f"{L.bands} bands" if L.bands > 1 else f"single band, default map {default_cmap}"
        self.info.setText(f"{L.name}: {L.modality}{unit}, {kind}")
        self._show_histogram(L, s)
        self._loading = False

    def _show_histogram(self, L: Layer, s: DisplaySettings) -> None:
        """The layer's histogram with the limits the rendering uses (absolute, else the percentiles')."""
        hist = L.histogram() if L.bands == 1 else None
        lim = None
        if hist is not None:
            try:
                lim = s.limits if s.limits is not None else L.percentile_limits(s.percentiles)
            except (ValueError, TypeError):
                lim = None
        self.histogram.set_data(hist, lim, L.unit)

    def _edited(self) -> None:
        if self._loading:
            return
        name = self.layer.currentText()
        if name not in self.layers:
            return
        lo, hi = self.lo.value(), self.hi.value()
        bad = hi <= lo
        for sb in (self.lo, self.hi):  # inverted limits are refused, visibly (never silently bent)
            sb.setStyleSheet("QDoubleSpinBox { background: #ffd6d6; }" if bad else "")
            sb.setToolTip("the lower limit must be below the upper limit" if bad else "")
        self.limits_note.setVisible(bad)
        if bad:
            return
        bands = tuple(sb.value() for sb in self.bands) if self.mode.currentData() == "bands" else None
        self.band_row.setEnabled(bands is not None)
        absolute = self.limit_mode.currentData() == "absolute"
        self.lock.setEnabled(absolute)
        old = self.settings_for(name)
        pct = old.percentiles if absolute else (lo, hi)
        st = DisplaySettings(self.cmap.currentData(), pct, bands, (lo, hi) if absolute else None,
                             absolute and self.lock.isChecked())
        # the owner (the workspace's session) stores it when the throttled signal arrives
        self._pending = (name, st)
        self._show_histogram(self.layers[name], st)
        self._timer.start()

    # ------------------------------------------------------------------ limits: percentiles or absolute
    def _set_limit_kind(self, kind: str, unit: str = "") -> None:
        for sb in (self.lo, self.hi):
            sb.blockSignals(True)
            if kind == "absolute":
                sb.setRange(-1e9, 1e9)
                sb.setDecimals(2)
                sb.setSingleStep(0.5)
                sb.setSuffix(f" {unit}" if unit else "")
            else:
                sb.setRange(0.0, 100.0)
                sb.setDecimals(1)
                sb.setSingleStep(0.5)
                sb.setSuffix(" %")
            sb.blockSignals(False)

    def _limit_kind_changed(self) -> None:
        """Switching to absolute starts from the limits the percentiles gave (what is on screen)."""
        if self._loading:
            return
        L = self.layers.get(self.layer.currentText())
        if L is None:
            return
        kind = self.limit_mode.currentData()
        s = self.settings_for(L.name)
        self._loading = True
        self._set_limit_kind(kind, L.unit)
        if kind == "absolute":
            try:  # remembered from the colour bar; a cube's HitImage is not expanded
                lo, hi = L.percentile_limits(s.percentiles)
            except (ValueError, TypeError):
                lo, hi = 0.0, 1.0
            lo, hi = float(lo), float(hi)
        else:
            lo, hi = s.percentiles
        self.lo.setValue(lo)
        self.hi.setValue(hi)
        self._loading = False
        self._edited()

    def _emit(self) -> None:
        pending, self._pending = getattr(self, "_pending", None), None
        if pending is not None:
            self.changed.emit(*pending)

    # for tests and scripted use
    def apply(self, name: str, settings: DisplaySettings) -> None:
        self.changed.emit(name, settings)  # the owner stores it (the workspace: session.set_display)
        self.settings.setdefault(name, settings)  # a panel without an owner keeps it itself
        if self.layer.currentText() == name:
            self._show_layer()
