"""Page 5: extrinsics — N x N epipolar error table and a 3D view of frusta and board poses."""

from __future__ import annotations

import numpy as np
from PySide6.QtCore import QEvent, Qt
from PySide6.QtWidgets import QGroupBox, QHeaderView, QLabel, QSplitter, QVBoxLayout, QWidget

from . import results
from .page import WizardPage
from .frusta_view import FrustaView, legend_html
from .widgets import banner, fill_matrix, fmt, grade_legend, item, make_table, set_banner


def _note(text: str) -> QLabel:
    lab = QLabel(text)
    lab.setWordWrap(True)
    lab.setStyleSheet("color: #444444;")
    return lab


class ExtrinsicsPage(WizardPage):
    title = "Extrinsics"

    def __init__(self, model, actions) -> None:
        super().__init__(model, actions)
        lay = QVBoxLayout(self)
        self.message = banner()
        lay.addWidget(self.message)
        split = QSplitter(Qt.Orientation.Horizontal)
        left = QWidget()
        ll = QVBoxLayout(left)
        ll.setContentsMargins(0, 0, 0, 0)
        # short group titles, the rest in wrapped labels: a group box is at least as wide as its
        # title, and two long ones made the page scroll sideways at 1280 px (the 3D view's legend cut)
        g = QGroupBox("Extrinsic (epipolar) error")
        gl = QVBoxLayout(g)
        gl.addWidget(_note("Distance of the target camera's corner to the epipolar line of the origin "
                           "camera's corner."))
        self.table = make_table()
        gl.addWidget(self.table)
        gl.addWidget(grade_legend())
        ll.addWidget(g)
        g2 = QGroupBox("Camera poses in the rig frame")
        g2l = QVBoxLayout(g2)
        g2l.addWidget(_note("The rig frame is the reference camera's frame: optical centre, rotation angle, "
                            "and their standard errors (±)."))
        self.poses = make_table()
        g2l.addWidget(self.poses)
        ll.addWidget(g2)
        # what a red cell means, and why it may be red here (hidden without red cells); under both
        # tables: its ten lines above the poses pushed them below a 720 px window's fold
        self.red_note = banner()
        self.red_note.setAlignment(Qt.AlignmentFlag.AlignLeft | Qt.AlignmentFlag.AlignTop)
        self._sizing = False
        self.red_note.installEventFilter(self)  # its whole text, at any width (see eventFilter)
        ll.addWidget(self.red_note)
        ll.addStretch(1)
        split.addWidget(left)
        right = QWidget()
        rl = QVBoxLayout(right)
        rl.setContentsMargins(0, 0, 0, 0)
        self.view3d = FrustaView()
        rl.addWidget(self.view3d, 1)
        # the legend under the view, not in it: a legend drawn in the scene is as wide as a fixed
        # share of the view, and a narrow view (a 1280 px window) cut the camera names
        self.legend = QLabel()
        self.legend.setWordWrap(True)
        self.legend.setTextFormat(Qt.TextFormat.RichText)
        rl.addWidget(self.legend)
        cap = _note("Camera frusta and the calibrated board poses. Drag to rotate, wheel to zoom.")
        rl.addWidget(cap)
        split.addWidget(right)
        # the tables need ~560 px for four cameras' names and the poses' nine columns; the 3D view
        # takes the rest (at 1280 px a 50/50 split cut "→ hyperspectral" and the names)
        split.setStretchFactor(0, 3)
        split.setStretchFactor(1, 2)
        split.setSizes([780, 520])
        lay.addWidget(split, 1)
        self._drawn = None
        self.model.calibration_changed.connect(self.refresh_later)
        self.model.report_changed.connect(self.refresh_later)

    def eventFilter(self, obj, event) -> bool:  # noqa: N802 (Qt name)
        # a wrapped label in a scrolled page gets squeezed below the height its text needs (the
        # note's first and last lines were cut at 1280 x 720): it asks for that height, the page scrolls
        if obj is self.red_note and event.type() in (QEvent.Type.Resize, QEvent.Type.Show) and not self._sizing:
            self._sizing = True  # setting the height resizes the note at once (a top-level page: recursion)
            try:
                need = self._note_height()
                if need > 0 and need != self.red_note.minimumHeight():
                    self.red_note.setMinimumHeight(need)
            finally:
                self._sizing = False
        return False

    def _note_height(self) -> int:
        """The red note's height for its width; a line more, as its style sheet's padding and border
        are not counted (its last line was still cut)."""
        if not self.red_note.text():
            return 0
        return self.red_note.heightForWidth(self.red_note.width()) + self.red_note.fontMetrics().lineSpacing()

    def refresh(self) -> None:
        cal, rep = self.model.calibration, self.model.report
        if rep is None:
            self.table.setRowCount(0)
            set_banner(self.message, "Computing the error tables…" if self.actions.is_busy()
                       else "No error tables yet: they are computed when you come to this page.")
        else:
            set_banner(self.message, "Out of date: the calibration changed. Going Next or coming back recomputes."
                       if self.model.report_stale else "")
            names = results.camera_names(cal, self.model.session)
            fill_matrix(self.table, names, results.table(rep, "extrinsic"), "extrinsic")
            self.table.resizeRowsToContents()  # as tall as its rows: no stretched cells, no scroll bar
            self.table.setFixedHeight(self.table.horizontalHeader().sizeHint().height()
                                      + sum(self.table.rowHeight(i) for i in range(self.table.rowCount()))
                                      + 2 * self.table.frameWidth() + 2)
        note = results.red_cells_note(rep, cal if self.model.calibration_ready() else None) if rep is not None else ""
        self.red_note.setText(note)
        self.red_note.setVisible(bool(note))
        self.red_note.setMinimumHeight(self._note_height())
        if cal is not None:
            rig = cal.rig
            self.poses.clear()
            # two-line headers: nine one-line ones needed a sideways scroll even at 1500 px
            cols = [("camera", "camera name (the depth camera and the reference camera are marked)"),
                    ("x\nmm", "optical centre in the rig frame, x (mm)"),
                    ("y\nmm", "optical centre in the rig frame, y (mm)"),
                    ("z\nmm", "optical centre in the rig frame, z (mm)"),
                    ("rotation\n°", "rotation angle from the reference camera (degrees)"),
                    ("distance\nmm", "distance of the optical centre from the reference camera's (mm)"),
                    ("± rot.\n°", "standard error of the rotation (degrees)"),
                    ("± transl.\nmm", "standard error of the translation (mm)"),
                    ("σ rig px\nmed / worst", "the pose's uncertainty seen in this camera's image: the "
                     "standard error of a projected point due to the rig pose, median and worst over the "
                     "image at the working distance (px)")]
            unc = results.uncertainty(cal)
            self.poses.setColumnCount(len(cols))
            self.poses.setHorizontalHeaderLabels([c for c, _ in cols])
            for j, (_c, tip) in enumerate(cols):
                self.poses.horizontalHeaderItem(j).setToolTip(tip)
            self.poses.setRowCount(len(rig.cameras))
            for i, c in enumerate(rig.cameras):
                ctr = c.center_rig * 1000
                ang = float(np.degrees(np.linalg.norm(c.rvec)))
                u = unc.get(c.name)
                ref = u is None or u.rotation_deg is None
                rig_sig = u.summary("rig") if u is not None else None
                tags = [t for t, on in (("depth", c.name == rig.depth_camera), ("reference", ref)) if on]
                vals = [c.name + (f"\n({', '.join(tags)})" if tags else ""),
                        fmt(ctr[0], 1), fmt(ctr[1], 1), fmt(ctr[2], 1), fmt(ang, 2), fmt(np.linalg.norm(ctr), 1),
                        "–" if ref else f"{u.rotation_deg:.3f}", "–" if ref else f"{u.translation_mm:.2f}",
                        f"{rig_sig[0]:.2f} / {rig_sig[1]:.2f}" if rig_sig and not ref else "–"]
                for j, v in enumerate(vals):
                    self.poses.setItem(i, j, item(v, bold=(j == 0)))
            hh = self.poses.horizontalHeader()
            hh.setSectionResizeMode(QHeaderView.ResizeMode.ResizeToContents)
            hh.setSectionResizeMode(0, QHeaderView.ResizeMode.Stretch)  # the names take what is left
            hh.setStretchLastSection(False)  # (a stretched last section could be narrower than its text)
            self.poses.resizeRowsToContents()
            h = self.poses.horizontalHeader().height() + sum(self.poses.rowHeight(i) for i in range(len(rig.cameras)))
            # nine columns may need the horizontal scroll bar: keep every camera's row visible (as page 4)
            h += self.poses.horizontalScrollBar().sizeHint().height()
            self.poses.setFixedHeight(h + 2 * self.poses.frameWidth() + 2)
            if self._drawn is not cal:
                self._drawn = cal
                self.view3d.set_scene(list(rig.cameras), results.board_outlines(cal, self.model.session))
                self.legend.setText(legend_html([c.name for c in rig.cameras]))
