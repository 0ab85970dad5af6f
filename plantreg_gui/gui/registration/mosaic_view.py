"""Mosaic view: tiles alternating modalities (the paper's mosaic figure), a checkerboard and a
blend between two chosen modalities, and a flicker toggle (3D Slicer's compare tools)."""

from __future__ import annotations

import numpy as np
from PySide6.QtCore import Qt, QTimer, Signal
from PySide6.QtWidgets import (
    QCheckBox, QComboBox, QHBoxLayout, QLabel, QSlider, QSpinBox, QVBoxLayout, QWidget,
)

from ...core.display import display
from .image_views import ImageView

MODES = {"mosaic": "Mosaic (all modalities)", "checkerboard": "Checkerboard A | B", "blend": "Blend A → B"}


class MosaicView(QWidget):
    hovered = Signal(str, int, int)

    def __init__(self, parent: QWidget | None = None):
        super().__init__(parent)
        self.renders: dict[str, np.ndarray] = {}
        self.order: list[str] = []
        self.view = ImageView("mosaic")
        self.view.hovered.connect(lambda r, c: self.hovered.emit("mosaic", r, c))

        self.mode = QComboBox()
        for k, t in MODES.items():
            self.mode.addItem(t, k)
        self.a = QComboBox()
        self.b = QComboBox()
        self.tile = QSpinBox()
        self.tile.setRange(4, 2048)
        self.tile.setValue(64)
        self.tile.setSuffix(" px")
        self.tile.setToolTip("tile size of the mosaic and checkerboard")
        self.tile_slider = QSlider(Qt.Orientation.Horizontal)
        self.tile_slider.setRange(4, 400)
        self.tile_slider.setValue(64)
        self.tile_slider.setMaximumWidth(140)
        self.tile_slider.valueChanged.connect(self.tile.setValue)
        self.tile.valueChanged.connect(self._tile_to_slider)
        self.alpha = QSlider(Qt.Orientation.Horizontal)
        self.alpha.setRange(0, 100)
        self.alpha.setValue(50)
        self.alpha.setMaximumWidth(160)
        self.alpha.setToolTip("blend: 0 = A only, 100 = B only")
        self.flicker = QCheckBox("Flicker A/B")
        self.flicker.setToolTip("alternate between A and B twice a second")
        self._flick_timer = QTimer(self)
        self._flick_timer.setInterval(500)
        self._flick_timer.timeout.connect(self._flick)
        self._flick_state = 0

        for c in (self.mode, self.a, self.b):
            # as wide as their longest entry where there is room ("Mosaic (a" was cut at 1280 px),
            # down to four characters in a narrow window: the combos give way, not the window
            c.setSizeAdjustPolicy(QComboBox.SizeAdjustPolicy.AdjustToMinimumContentsLengthWithIcon)
            c.setMinimumContentsLength(4)
            c.setMinimumWidth(c.minimumSizeHint().width())
            c.setSizeAdjustPolicy(QComboBox.SizeAdjustPolicy.AdjustToContents)
        top = QHBoxLayout()
        top.addWidget(QLabel("Mode"))
        top.addWidget(self.mode)
        top.addSpacing(8)
        self._a_label, self._b_label = QLabel("A"), QLabel("B")
        self._tile_label, self._alpha_label = QLabel("Tile"), QLabel("Blend")
        top.addWidget(self._a_label)
        top.addWidget(self.a)
        top.addWidget(self._b_label)
        top.addWidget(self.b)
        top.addSpacing(8)
        top.addWidget(self._tile_label)
        top.addWidget(self.tile)
        top.addWidget(self.tile_slider)
        top.addSpacing(8)
        top.addWidget(self._alpha_label)
        top.addWidget(self.alpha)
        top.addStretch(1)
        self.caption = QLabel("")
        self.caption.setWordWrap(True)  # a narrow window wraps it rather than widening
        # flicker beside the caption (which says what is shown): in the top row it left the mode
        # combo too little room at 1280 px
        bottom = QHBoxLayout()
        bottom.addWidget(self.caption, 1)
        bottom.addWidget(self.flicker)
        lay = QVBoxLayout(self)
        lay.setContentsMargins(2, 2, 2, 2)
        lay.addLayout(top)
        lay.addWidget(self.view, 1)
        lay.addLayout(bottom)

        for w in (self.mode, self.a, self.b):
            w.currentIndexChanged.connect(self.update_view)
        self.tile.valueChanged.connect(self.update_view)
        self.alpha.valueChanged.connect(self.update_view)
        self.flicker.toggled.connect(self._toggle_flicker)
        self._sync_controls()

    def _tile_to_slider(self, v: int) -> None:
        # the slider covers 4-400 px only; a larger typed tile must not be pulled back to 400
        self.tile_slider.blockSignals(True)
        self.tile_slider.setValue(min(v, self.tile_slider.maximum()))
        self.tile_slider.blockSignals(False)

    # ------------------------------------------------------------------ data
    def set_renders(self, renders: dict[str, np.ndarray], order: list[str],
                    focus: tuple[int, int] | None = None) -> None:
        """``renders[name]`` (H, W, 3) uint8 of one grid; ``order`` the modalities of the mosaic;
        ``focus`` (h, w) of the region of interest, which sets the default tile size."""
        self.renders = renders
        names = [n for n in order if n in renders]
        if names != self.order:
            self.order = names
            for combo, default in ((self.a, 0), (self.b, 1)):
                combo.blockSignals(True)
                combo.clear()
                combo.addItems(names)
                combo.setCurrentIndex(min(default, len(names) - 1))
                combo.blockSignals(False)
            if names:
                h, w = focus or renders[names[0]].shape[:2]
                self.tile.blockSignals(True)
                self.tile.setValue(display.default_tile((h, w)))
                self.tile_slider.setValue(self.tile.value())
                self.tile.blockSignals(False)
        self.update_view()

    def current_mode(self) -> str:
        return self.mode.currentData()

    def set_mode(self, mode: str) -> None:
        self.mode.setCurrentIndex(list(MODES).index(mode))

    def composite(self) -> np.ndarray | None:
        """The picture the view shows for the current controls, (H, W, 3) uint8."""
        if not self.order:
            return None
        mode = self.current_mode()
        a = self.renders.get(self.a.currentText(), self.renders[self.order[0]])
        b = self.renders.get(self.b.currentText(), a)
        if self.flicker.isChecked():
            return a if self._flick_state == 0 else b
        if mode == "mosaic":
            return display.mosaic([self.renders[n] for n in self.order], self.tile.value())
        if mode == "checkerboard":
            return display.checkerboard(a, b, self.tile.value())
        return display.blend(a, b, self.alpha.value() / 100.0)

    def _sync_controls(self) -> None:
        """Enable only the controls the current mode uses (a live control that changes nothing
        reads as a fault): A/B for checkerboard, blend and flicker; the tile size for mosaic and
        checkerboard; the blend slider for blend."""
        mode, flick = self.current_mode(), self.flicker.isChecked()
        two = flick or mode in ("checkerboard", "blend")
        for w in (self.a, self.b, self._a_label, self._b_label):
            w.setEnabled(two)
        tiles = not flick and mode in ("mosaic", "checkerboard")
        for w in (self.tile, self.tile_slider, self._tile_label):
            w.setEnabled(tiles)
        for w in (self.alpha, self._alpha_label):
            w.setEnabled(not flick and mode == "blend")

    def update_view(self) -> None:
        self._sync_controls()
        img = self.composite()
        if img is None:
            self.view.clear()
            self.caption.setText("Register the recording to compare modalities.")
            return
        self.view.set_rgb8(img)
        mode = self.current_mode()
        a, b = self.a.currentText(), self.b.currentText()
        if self.flicker.isChecked():
            txt = f"Flicker: showing {a if self._flick_state == 0 else b}"
        elif mode == "mosaic":
            txt = f"Mosaic of {', '.join(self.order)}: tile (i, j) shows modality (i + j) mod {len(self.order)}, " \
                  f"{self.tile.value()} px tiles"
        elif mode == "checkerboard":
            txt = f"Checkerboard: {a} (top-left) and {b}, {self.tile.value()} px tiles"
        else:
            txt = f"Blend: {100 - self.alpha.value()}% {a} + {self.alpha.value()}% {b}"
        self.caption.setText(txt)

    # ------------------------------------------------------------------ flicker
    def _toggle_flicker(self, on: bool) -> None:
        self._flick_state = 0
        if on:
            self._flick_timer.start()
        else:
            self._flick_timer.stop()
        self.update_view()

    def _flick(self) -> None:
        self._flick_state ^= 1
        self.update_view()

    def shutdown(self) -> None:  # the workspace's view hook (views.py)
        self.stop()

    def stop(self) -> None:
        self._flick_timer.stop()

    # ------------------------------------------------------------------ the workspace's session
    needs = "result"

    def bind(self, session) -> "MosaicView":
        """Show ``session``'s registered renderings; hovering moves its cursor."""
        from .image_views import home_rect
        from ...models.layers import DEPTH

        def refresh() -> None:
            cams = [L.name for L in session.layers if L.name != DEPTH]
            home = home_rect(session.home)
            self.view.set_home(home)
            self.set_renders(session.renders, cams, None if home is None else (int(home.height()), int(home.width())))

        session.events.result.connect(refresh)
        session.events.display.connect(lambda _name: self.update_view())
        self.hovered.connect(lambda _src, r, c: session.hover("target", r, c))
        return self
