"""Page 4: intrinsics — per-camera table and per-view error bars (click a bar to review the view)."""

from __future__ import annotations

from PySide6.QtCore import Qt
from PySide6.QtWidgets import QHBoxLayout, QHeaderView, QLabel, QPushButton, QSplitter, QVBoxLayout

from . import results
from .page import WizardPage
from .charts import PerViewChart, UncertaintyMap
from .widgets import banner, fmt, grade_colour, item, make_table, set_banner


class IntrinsicsPage(WizardPage):
    title = "Intrinsics"

    def __init__(self, model, actions) -> None:
        super().__init__(model, actions)
        lay = QVBoxLayout(self)
        self.message = banner()
        lay.addWidget(self.message)
        split = self.split = QSplitter(Qt.Orientation.Vertical)
        self.table = make_table(stretch=False)
        self.table.horizontalHeader().setSectionResizeMode(QHeaderView.ResizeMode.Stretch)
        split.addWidget(self.table)
        self.chart = PerViewChart()
        self.chart.bar_clicked.connect(self._bar)
        lower = QSplitter(Qt.Orientation.Horizontal)
        lower.addWidget(self.chart)
        self.umap = UncertaintyMap()
        self._umap_tip = ("Projection uncertainty over each camera's image (px; mrcal's figure, the worst over "
                             "0.8-1.25x the boards' distance): how far a point may project from where the "
                             "calibration puts it (1 sigma, least certain direction). Green: well within the camera's limit; red: at or beyond it. Hatched: no "
                             "board corner was seen there. Outlined (when a limit is exceeded): where more board views "
                             "would shrink it most.")
        self.umap.setToolTip(self._umap_tip)
        lower.addWidget(self.umap)
        lower.setSizes([700, 450])
        split.addWidget(lower)
        split.setSizes([200, 560])
        lay.addWidget(split, 1)
        self.worst = QLabel()
        self.worst.setWordWrap(True)
        lay.addWidget(self.worst)
        hint = QLabel("Left: each bar is one view's mean reprojection error; orange bars are the views the "
                      "calibration flags as weak, hatched grey bars marked ✖ the views you excluded (their error "
                      "with the final model), the dashed line is the camera's mean. Click a bar to "
                      "inspect that view (page 3) and reject it there. Right: how uncertain each camera's "
                      "projection still is (px, 1 sigma); record more board views, tilted, where it is red or "
                      "outlined. ± values in the table are standard errors.")
        hint.setWordWrap(True)
        hint.setStyleSheet("color: #444444;")
        lay.addWidget(hint)
        hb = QHBoxLayout()
        self.exclude_btn = QPushButton("Exclude weak views and recalibrate")
        self.exclude_btn.clicked.connect(self.exclude_weak)
        self.recal_btn = QPushButton("Recalibrate")
        self.recal_btn.clicked.connect(lambda: self.actions.recalibrate())
        hb.addStretch(1)
        hb.addWidget(self.recal_btn)
        hb.addWidget(self.exclude_btn)
        lay.addLayout(hb)
        self.model.calibration_changed.connect(self.refresh_later)
        self.model.report_changed.connect(self.refresh_later)
        self.model.review_changed.connect(self.refresh_later)
        actions.busy_changed.connect(self._on_busy)

    def _on_busy(self, busy) -> None:
        self._buttons()
        if self.model.calibration is None:
            self._banner()

    def _banner(self) -> None:
        if self.actions.is_busy():
            set_banner(self.message, "Calibrating… (the results appear here when done)")
        elif self.actions.last_error and self.model.session is not None:
            set_banner(self.message, f"⚠ The calibration failed: {self.actions.last_error}", error=True)
        else:
            set_banner(self.message, "Not calibrated yet: the calibration runs when you come to this page.")

    def _buttons(self) -> None:
        busy = self.actions.is_busy()
        weak = results.weak_views(self.model.calibration) if self.model.calibration_ready() else set()
        weak -= self.model.excluded
        self.exclude_btn.setText(f"Exclude {len(weak)} weak view{'s' if len(weak) != 1 else ''} and recalibrate"
                                 if weak else "No weak views to exclude")
        self.exclude_btn.setEnabled(not busy and bool(weak))
        self.recal_btn.setEnabled(not busy and self.model.session is not None)

    def refresh(self) -> None:
        cal = self.model.calibration
        self._buttons()
        if cal is None:
            self.table.setRowCount(0)
            self.chart.set_data({}, {}, {})
            self.umap.set_data([])
            self.worst.setText("")
            self._banner()
            return
        if self.model.calibration_stale:
            set_banner(self.message, "The detections or exclusions changed since this calibration: "
                                     "'Recalibrate' to update (or go Next, which recalibrates).")
        elif results.uncertainty_problems(cal):
            set_banner(self.message, "⚠ The views do not determine this calibration well enough: "
                       + " ".join(p + "." for p in results.uncertainty_problems(cal))
                       + " Saving it needs your explicit confirmation.", error=True)
        else:
            set_banner(self.message, "")
        rows = results.intrinsic_rows(cal, self.model.report if self.model.report_ready() else None)
        # two-line headers and cells: at 1280 px one-line ones left the distortion column a few pixels
        cols = ["camera", "fx", "fy", "cx", "cy", "lens\nmodel", "distortion\n(k1 k2 p1 p2 k3 …)",
                "uncertainty px\n(median / worst)", "error\npx", "error\nnorm.", "views", "weak\nviews"]
        self.table.clear()
        self.table.setColumnCount(len(cols))
        self.table.setHorizontalHeaderLabels(cols)
        self.table.setRowCount(len(rows))
        names = ("k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6")
        for i, r in enumerate(rows):
            sd = r["std"]
            sig = r["sigma"]
            # value over its standard error: four narrower columns leave the distortion one room
            pms = [results.pm(r[k], sd.get(k)).replace(" ± ", "\n± ") for k in ("fx", "fy", "cx", "cy")]
            vals = [r["camera"], *pms, r["model"],
                    " ".join(f"{d:+.4f}" for d in r["dist"][:5]) + (" …" if len(r["dist"]) > 5 else ""),
                    f"{sig[0]:.2f} / {sig[1]:.2f}" if sig else "–",
                    fmt(r["px"], 3), fmt(r["normalized"], 3), str(r["views"]),
                    ", ".join(p.replace("pose_", "") for p in r["weak"]) or "none"]
            for j, v in enumerate(vals):
                it = item(v, bold=(j == 0))
                if j in (8, 9):
                    it.setBackground(grade_colour(r["normalized"]))
                if j == 5:
                    cv = ", ".join(f"{k}: {v:.3f} px" for k, v in r["model_cv"].items() if v is not None)
                    it.setToolTip(f"Chosen because it {r['model_reason']}." if r["model_reason"].startswith("predicts")
                                  else r["model_reason"])
                    if cv:
                        it.setToolTip(it.toolTip() + "\nError predicting views it was not fitted to: " + cv)
                if j == 6:
                    it.setToolTip("OpenCV distortion coefficients ± standard error:\n" + "\n".join(
                        f"{names[k]} = {results.pm(d, sd.get(names[k]), 6)}" for k, d in enumerate(r["dist"])))
                if j == 7:
                    it.setToolTip("Projection uncertainty over the image (1 sigma, px; mrcal's figure, the worst over "
                                  "0.8-1.25x the boards' distance): median and worst; see the heat map")
                self.table.setItem(i, j, it)
        hh = self.table.horizontalHeader()
        hh.setSectionResizeMode(QHeaderView.ResizeMode.ResizeToContents)
        hh.setSectionResizeMode(6, QHeaderView.ResizeMode.Stretch)
        self.table.resizeRowsToContents()
        h = self.table.horizontalHeader().height() + sum(self.table.rowHeight(i) for i in range(len(rows)))
        # the distortion column may need the horizontal scroll bar: keep every camera's row visible
        h += 2 * self.table.frameWidth() + 2 + self.table.horizontalScrollBar().sizeHint().height()
        self.table.setMinimumHeight(h)
        self.table.setMaximumHeight(h)
        self.split.setSizes([h, max(self.split.height() - h, 300)])
        per_view = results.per_view_px(cal)
        weak = results.weak_by_camera(cal)
        mean = {r["camera"]: r["px"] for r in rows}
        ex = results.excluded_px(cal, self.model.excluded, self.model.detections)
        per_view = {c: {p: v for p, v in pv.items() if p not in ex.get(c, {})} for c, pv in per_view.items()}
        self.chart.set_data(per_view, weak, mean, excluded=ex)
        maps = results.uncertainty_maps(cal)
        self.umap.set_data(maps)
        details = [m["detail"] for m in maps if m.get("detail")]
        self.umap.setToolTip(self._umap_tip + ("\n\n" + "\n".join(details) if details else ""))
        # mrcal-style: the worst views first, across cameras (on the normalised error)
        norm = {n: float(c.normalization) for n, c in cal.intrinsics.items()}
        worst = sorted(((px * norm[c], c, p, px) for c, v in per_view.items() for p, px in v.items()), reverse=True)[:6]
        self.worst.setText("<b>Worst views first:</b> " + ", ".join(
            f"{c} {p} {px:.3f} px ({nn:.3f} norm.)" for nn, c, p, px in worst))

    def _bar(self, camera: str, pose: str) -> None:
        self.actions.show_view(camera, pose)

    def exclude_weak(self) -> None:
        weak = results.weak_views(self.model.calibration) if self.model.calibration is not None else set()
        if not weak:
            return
        self.model.set_excluded_many(weak, True)
        self.actions.recalibrate()
