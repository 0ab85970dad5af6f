"""Page 6: depth — N x N depth error table, ToF bias per pose, per-view breakdown."""

from __future__ import annotations

from PySide6.QtCore import Qt
from PySide6.QtWidgets import QComboBox, QGroupBox, QHBoxLayout, QLabel, QSplitter, QVBoxLayout, QWidget

from . import results
from .page import WizardPage
from .charts import BiasChart
from .widgets import banner, fill_matrix, fmt, grade_colour, grade_legend, item, make_table, set_banner


class DepthPage(WizardPage):
    title = "Depth"

    def __init__(self, model, actions) -> None:
        super().__init__(model, actions)
        lay = QVBoxLayout(self)
        self.message = banner()
        lay.addWidget(self.message)
        split = QSplitter(Qt.Orientation.Horizontal)
        left = QWidget()
        ll = QVBoxLayout(left)
        ll.setContentsMargins(0, 0, 0, 0)
        g = QGroupBox("Depth error: origin corners through the depth map's mesh into the target camera")
        gl = QVBoxLayout(g)
        self.table = make_table()
        gl.addWidget(self.table, 1)
        gl.addWidget(grade_legend())
        ll.addWidget(g, 1)
        g2 = QGroupBox("ToF depth bias per pose")
        g2l = QVBoxLayout(g2)
        self.bias = BiasChart()
        g2l.addWidget(self.bias)
        ll.addWidget(g2, 1)
        split.addWidget(left)
        g3 = QGroupBox("Per-view breakdown: depth error per pose (px and normalised), worst first")
        g3l = QVBoxLayout(g3)
        hb = QHBoxLayout()
        hb.addWidget(QLabel("Origin camera:"))
        self.origin = QComboBox()
        self.origin.currentIndexChanged.connect(self._fill_views)
        hb.addWidget(self.origin, 1)
        g3l.addLayout(hb)
        self.views = make_table(stretch=True)
        g3l.addWidget(self.views)
        # the cells show both numbers the colour is about (defect 9: px shown, normalised coloured)
        self.views_legend = grade_legend("Rows: poses, worst first; columns: target cameras. Cells: mean depth "
                                         "error in pixels of the target and normalised (× 1000/√(h·w) of the "
                                         "target), as in the table on the left.")
        g3l.addWidget(self.views_legend)
        split.addWidget(g3)
        split.setSizes([760, 560])
        lay.addWidget(split, 1)
        self.model.report_changed.connect(self.refresh_later)

    def refresh(self) -> None:
        rep, cal, s = self.model.report, self.model.calibration, self.model.session
        if s is not None and s.depth_camera is None:
            set_banner(self.message, "This rig has no depth camera: there is no depth error table "
                                     "and no ToF bias. Go on to Save.")
        elif rep is None:
            set_banner(self.message, "Computing the error tables…" if self.actions.is_busy()
                       else "No error tables yet: they are computed when you come to this page.")
        else:
            set_banner(self.message, "Out of date: the calibration changed." if self.model.report_stale else "")
        if rep is None or (s is not None and s.depth_camera is None):
            self.table.setRowCount(0)
            self.views.setRowCount(0)
            self.bias.set_data({}, {})
            return
        names = results.camera_names(cal, s)
        fill_matrix(self.table, names, results.table(rep, "depth") or {}, "depth")
        dist = results.bias_distance_mm(rep) or results.board_distance_mm(cal)
        self.bias.set_data(results.depth_bias(rep), dist)
        self._rows, pairs = results.depth_views(rep)
        rank = {n: i for i, n in enumerate(names)}  # the N x N table's camera order, not alphabetical
        self._pairs = sorted(pairs, key=lambda pr: (rank.get(pr[0], len(rank)), rank.get(pr[1], len(rank))))
        origins = [o for o in names if any(pr[0] == o for pr in self._pairs)]
        cur = self.origin.currentText()
        self.origin.blockSignals(True)
        self.origin.clear()
        self.origin.addItems(origins)
        if cur in origins:
            self.origin.setCurrentText(cur)
        self.origin.blockSignals(False)
        self._fill_views()

    def _fill_views(self) -> None:
        o = self.origin.currentText()
        pairs = [pr for pr in getattr(self, "_pairs", []) if pr[0] == o]
        rows = []
        for pose, vals in getattr(self, "_rows", []):
            cells = [vals.get(pr) for pr in pairs]
            px = [c["px"] for c in cells if c and c.get("px") is not None]
            if px:
                rows.append((max(px), pose, cells))
        rows.sort(key=lambda r: -r[0])
        self.views.clear()
        self.views.setColumnCount(1 + len(pairs))
        self.views.setHorizontalHeaderLabels(["pose"] + [f"{o} → {t}" for _o, t in pairs])
        self.views.setRowCount(len(rows))
        for i, (_worst, pose, cells) in enumerate(rows):
            self.views.setItem(i, 0, item(pose, bold=True))
            for j, c in enumerate(cells):
                if c and c.get("px") is not None:
                    nn = c.get("normalized", float("nan"))
                    it = item(f"{fmt(c['px'], 3)} px\n{fmt(nn, 3)} norm.", bg=grade_colour(nn),
                              tooltip=f"{pose}: {o} → {pairs[j][1]}: {c['px']:.4f} px of {pairs[j][1]}, "
                                      f"{nn:.4f} normalised (colour)")
                else:
                    it = item("—")
                self.views.setItem(i, j + 1, it)
        self.views.resizeRowsToContents()
