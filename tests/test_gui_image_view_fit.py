"""The image views' fit: the home region (the object's box) is shown whole and the view settles.

Before, the views had scroll bars "as needed": fitting a region made a scroll bar appear, which
shrank the viewport, whose resize fitted again and took the bar away -- on the real areca palm
(registered into thermal, side-by-side view) the GUI thread went round that loop for minutes, and
a fit that ended with a bar shown cut the plant off at the bottom (the leopard lily's mosaic).
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from PySide6.QtCore import QRectF

pytestmark = [pytest.mark.gui, pytest.mark.timeout(120)]


@pytest.mark.parametrize("kind", ["ImageView", "PointView"])
def test_fit_shows_the_home_region_whole_and_settles(qtbot, kind):
    from PySide6.QtWidgets import QApplication

    from plantreg_gui.gui.landmarks.point_view import PointView
    from plantreg_gui.gui.registration.image_views import ImageView

    v = {"ImageView": ImageView, "PointView": PointView}[kind]("t")
    qtbot.addWidget(v)
    v.show()
    qtbot.waitExposed(v)
    resizes = []
    orig = v.resizeEvent

    def counting(e):
        resizes.append(e.size())
        orig(e)

    v.resizeEvent = counting
    rng = np.random.default_rng(3)
    for (w, h), (iw, ih) in itertools.product([(492, 344), (492, 330), (985, 690), (300, 420)],
                                             [(640, 576), (640, 480), (512, 512)]):
        v.set_rgb8(rng.integers(0, 255, (ih, iw, 3), dtype=np.uint8))
        for home in (None, QRectF(40, 30, iw - 90, ih - 40), QRectF(0, 0, iw, ih), QRectF(100, 0, 200, ih)):
            resizes.clear()
            v.resize(w, h)
            v.set_home(home)
            for _ in range(20):
                QApplication.processEvents()
            assert len(resizes) <= 4, f"view {w}x{h}, image {iw}x{ih}: {len(resizes)} resizes (a fit loop)"
            want = home if home is not None else QRectF(0, 0, iw, ih)
            seen = v.mapToScene(v.viewport().rect()).boundingRect()
            assert seen.adjusted(-1, -1, 1, 1).contains(want), (w, h, iw, ih, want, seen)
