"""Small display helpers shared by the wizard pages: image conversion, colour grading, tables."""

from __future__ import annotations

import math
from typing import Iterable

import numpy as np
from PySide6.QtCore import Qt
from PySide6.QtGui import QColor, QFont, QImage, QPixmap
from PySide6.QtWidgets import (QAbstractItemView, QHeaderView, QLabel, QSizePolicy, QTableWidget,
                               QTableWidgetItem)

from ...core.calibration.preview import thumbnail, to_display  # noqa: F401  (used by the pages)

#: Colour grade of the error tables, on the *normalised* error (px * 1000 / sqrt(h w)):
#: green at 0, yellow at GRADE_MID, red from GRADE_MAX on. The paper's real rig reaches
#: 0.1-2 normalised; above 3 a technician should look at the views.
GRADE_MID = 1.5
GRADE_MAX = 3.0

CAMERA_COLOURS = ["#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b", "#e377c2", "#17becf"]


def camera_colour(i: int) -> str:
    return CAMERA_COLOURS[i % len(CAMERA_COLOURS)]


def qimage(a: np.ndarray) -> QImage:
    """uint8 (H, W), (H, W, 3) RGB or (H, W, 4) RGBA -> QImage (a deep copy)."""
    a = np.ascontiguousarray(a)
    h, w = a.shape[:2]
    if a.ndim == 2:
        img = QImage(a.data, w, h, a.strides[0], QImage.Format.Format_Grayscale8)
    elif a.shape[2] == 3:
        img = QImage(a.data, w, h, a.strides[0], QImage.Format.Format_RGB888)
    else:
        img = QImage(a.data, w, h, a.strides[0], QImage.Format.Format_RGBA8888)
    return img.copy()


def qpixmap(a: np.ndarray) -> QPixmap:
    return QPixmap.fromImage(qimage(a))


def grade_colour(normalized: float) -> QColor:
    """Green -> yellow -> red for a normalised error (see GRADE_MID / GRADE_MAX); grey for NaN."""
    if normalized is None or not math.isfinite(normalized):
        return QColor("#dddddd")
    t = min(max(normalized / GRADE_MAX, 0.0), 1.0)
    # hue 120 (green) -> 60 (yellow) at GRADE_MID -> 0 (red)
    mid = GRADE_MID / GRADE_MAX
    hue = 120 - 60 * (t / mid) if t <= mid else 60 - 60 * (t - mid) / (1 - mid)
    return QColor.fromHsvF(max(hue, 0) / 360.0, 0.45, 1.0)


def fmt(v: float | None, digits: int = 2) -> str:
    if v is None:
        return "—"
    try:
        f = float(v)
    except (TypeError, ValueError):
        return str(v)
    if not math.isfinite(f):
        return "—"
    return f"{f:.{digits}f}"


def make_table(parent=None, stretch: bool = True) -> QTableWidget:
    t = QTableWidget(parent)
    t.setEditTriggers(QAbstractItemView.EditTrigger.NoEditTriggers)
    t.setSelectionBehavior(QAbstractItemView.SelectionBehavior.SelectRows)
    t.setAlternatingRowColors(False)
    t.verticalHeader().setVisible(False)
    t.verticalHeader().setSectionResizeMode(QHeaderView.ResizeMode.ResizeToContents)
    if stretch:
        t.horizontalHeader().setSectionResizeMode(QHeaderView.ResizeMode.Stretch)
    return t


def item(text: str, tooltip: str = "", align=Qt.AlignmentFlag.AlignCenter, bg: QColor | None = None,
         bold: bool = False) -> QTableWidgetItem:
    it = QTableWidgetItem(text)
    it.setTextAlignment(align)
    if tooltip:
        it.setToolTip(tooltip)
    if bg is not None:
        it.setBackground(bg)
        it.setForeground(QColor("black"))
    if bold:
        f = QFont()
        f.setBold(True)
        it.setFont(f)
    return it


def fill_matrix(table: QTableWidget, names: list[str], cell: dict, what: str) -> None:
    """Fill an N x N origin (rows) x target (columns) error table.

    ``cell[o][t]`` is ``{"px": float, "normalized": float}`` (missing -> '—'). Cells show the
    pixel error and the normalised error, coloured by the normalised error.
    """
    table.clear()
    table.verticalHeader().setVisible(True)
    table.setRowCount(len(names))
    table.setColumnCount(len(names))
    table.setHorizontalHeaderLabels([f"→ {n}" for n in names])
    table.setVerticalHeaderLabels([f"{n} →" for n in names])
    for i, o in enumerate(names):
        for j, t in enumerate(names):
            c = (cell.get(o) or {}).get(t) if isinstance(cell, dict) else None
            if o == t:
                table.setItem(i, j, item("", bg=QColor("#f0f0f0")))
                continue
            if not c:
                table.setItem(i, j, item("—", f"no {what} error from {o} to {t} (no shared views)",
                                         bg=QColor("#eeeeee")))
                continue
            px, nn = c.get("px"), c.get("normalized")
            table.setItem(i, j, item(f"{fmt(px)} px\n{fmt(nn)} norm.",
                                     f"{what} error, corners of {o} transported into {t}: "
                                     f"{fmt(px, 3)} px, normalised {fmt(nn, 3)}",
                                     bg=grade_colour(nn if nn is not None else float('nan'))))
    # rows share the table's height: big, readable cells instead of a strip and white space
    table.verticalHeader().setSectionResizeMode(QHeaderView.ResizeMode.Stretch)
    table.setMinimumHeight(table.horizontalHeader().height() + 44 * len(names) + 4)
    f = table.font()
    f.setPointSizeF(max(f.pointSizeF(), 10.5))
    table.setFont(f)


MATRIX_LEGEND = ("Rows: origin camera, columns: target camera. Cells: mean error in pixels of the target and "
                 "normalised (× 1000/√(h·w) of the target).")


def grade_legend(intro: str = MATRIX_LEGEND) -> QLabel:
    lab = QLabel(
        f"{intro} Colour on the normalised error: "
        f"<span style='background:{grade_colour(0).name()}'>&nbsp;good&nbsp;</span> "
        f"<span style='background:{grade_colour(GRADE_MID).name()}'>&nbsp;{GRADE_MID:g}&nbsp;</span> "
        f"<span style='background:{grade_colour(GRADE_MAX).name()}'>&nbsp;≥ {GRADE_MAX:g}&nbsp;</span>"
    )
    lab.setWordWrap(True)
    lab.setTextFormat(Qt.TextFormat.RichText)
    lab.setSizePolicy(QSizePolicy.Policy.Preferred, QSizePolicy.Policy.Minimum)
    return lab


def banner(text: str = "") -> QLabel:
    """An inline message line (hidden when empty): validation problems, stale results."""
    lab = QLabel(text)
    lab.setWordWrap(True)
    lab.setObjectName("banner")
    lab.setStyleSheet("QLabel#banner { background: #fff3cd; color: #5c4400; border: 1px solid #e0c060;"
                      " padding: 4px; border-radius: 3px; }")
    lab.setVisible(bool(text))
    return lab


def set_banner(lab: QLabel, text: str, error: bool = False) -> None:
    lab.setText(text)
    if error:
        lab.setStyleSheet("QLabel#banner { background: #f8d7da; color: #721c24; border: 1px solid #e0a0a8;"
                          " padding: 4px; border-radius: 3px; }")
    else:
        lab.setStyleSheet("QLabel#banner { background: #fff3cd; color: #5c4400; border: 1px solid #e0c060;"
                          " padding: 4px; border-radius: 3px; }")
    lab.setVisible(bool(text))


def sorted_keys(keys: Iterable[tuple[str, str]]) -> list[tuple[str, str]]:
    return sorted(keys)
