"""Page 7: save — ROI editor over a depth map, then the rig file, the report JSON and CSV tables.

Length: the ROI editor with its depth-map preview and fit, the file choice and the save with its
two confirmations (replacing files, an uncertain calibration) are one page.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
from PySide6.QtCore import Qt, QTimer
from PySide6.QtWidgets import (QComboBox, QDoubleSpinBox, QFileDialog, QFormLayout, QGridLayout,
                               QGroupBox, QHBoxLayout, QLabel, QLineEdit, QMessageBox, QPushButton,
                               QSizePolicy, QVBoxLayout)

from . import results
from .page import WizardPage
from .widgets import banner, qpixmap, set_banner

AXES = ("x", "y", "z")
PREVIEW_SIDE = 400  # pixels: the depth preview's longer side


class SavePage(WizardPage):
    title = "Save"

    def __init__(self, model, actions) -> None:
        super().__init__(model, actions)
        self._rays = None  # (calibration, step, grid shape, rays (h*w, 3) z=1 in the depth camera frame)
        self._depth_cache: dict[str, np.ndarray] = {}
        self.inside_fraction = float("nan")
        self._confirmed: set[str] = set()  # files the user agreed to replace
        self._roi_set = False
        lay = QHBoxLayout(self)

        # --- ROI over the depth map
        g = QGroupBox("Region of interest (rig frame = depth camera frame; max z is the ground plane)")
        gl = QVBoxLayout(g)
        top = QHBoxLayout()
        top.addWidget(QLabel("Depth map:"))
        # the calibration's board poses (to see the rig's view) and plant depth maps the user loads:
        # only a plant's depth map can set the ROI (a box around a board ends where the board was)
        self.pose = QComboBox()
        self.pose.currentIndexChanged.connect(self._source_changed)
        top.addWidget(self.pose, 1)
        self.load_btn = QPushButton("Load plant depth map…")
        self.load_btn.setToolTip("A depth map of a plant recording (depth.png / .tif, or the recording's "
                                 "recording.json), taken with this rig: the ROI is fitted to it")
        self.load_btn.clicked.connect(self._browse_plant)
        top.addWidget(self.load_btn)
        self.fit_btn = QPushButton("Fit ROI to the plant")
        self.fit_btn.setToolTip("x, y: the measured view (1st-99th percentile); z: from just in front of the "
                                "plant to 3 cm in front of the ground (the far surface)")
        self.fit_btn.clicked.connect(self.fit_roi)
        top.addWidget(self.fit_btn)
        gl.addLayout(top)
        self.image = QLabel()
        self.image.setAlignment(Qt.AlignmentFlag.AlignCenter)
        self.image.setWordWrap(True)  # its notes (no depth camera, ...) were cut at both ends at 1280 px
        self.image.setMargin(12)
        self.image.setSizePolicy(QSizePolicy.Policy.Ignored, QSizePolicy.Policy.Ignored)
        self.image.setMinimumSize(320, 240)
        self.image.setStyleSheet("background: #202020; color: #dddddd;")
        gl.addWidget(self.image, 1)
        self.legend = QLabel("Measured depth in grey inside the ROI (near = light); "
                             "<span style='color:#c00000'><b>red</b></span>: "
                             "outside the ROI; <span style='color:#1060ff'><b>blue</b></span>: beyond the ground "
                             "plane (z > max z). <span style='color:#b8a000'><b>Yellow</b></span>: the ROI box; "
                             "<span style='color:#00a0a0'><b>cyan</b></span>: the ground plane (its 10 cm grid "
                             "and where it meets the scene).")
        self.legend.setWordWrap(True)
        gl.addWidget(self.legend)
        grid = QGridLayout()
        self.spins: dict[str, QDoubleSpinBox] = {}
        grid.addWidget(QLabel(""), 0, 0)
        for j, a in enumerate(AXES):
            grid.addWidget(QLabel(f"<b>{a}</b> (m)"), 0, j + 1, Qt.AlignmentFlag.AlignCenter)
        for i, which in enumerate(("min", "max")):
            grid.addWidget(QLabel(which + (" (z = ground)" if which == "max" else "")), i + 1, 0)
            for j, a in enumerate(AXES):
                sp = QDoubleSpinBox()
                sp.setRange(-10.0, 20.0)
                sp.setDecimals(3)
                sp.setSingleStep(0.01)
                sp.valueChanged.connect(self._schedule)
                self.spins[f"{which}_{a}"] = sp
                grid.addWidget(sp, i + 1, j + 1)
        gl.addLayout(grid)
        self.roi_msg = banner()
        gl.addWidget(self.roi_msg)
        lay.addWidget(g, 3)

        # --- outputs
        o = QGroupBox("Outputs")
        ol = QVBoxLayout(o)
        f = QFormLayout()
        self.rig_path = QLineEdit()
        self.report_path = QLineEdit()
        for label, edit, kind in (("Rig file:", self.rig_path, "rig"), ("Report JSON:", self.report_path, "report")):
            row = QHBoxLayout()
            row.addWidget(edit, 1)
            b = QPushButton("…")
            b.setFixedWidth(30)
            b.clicked.connect(lambda _=False, k=kind: self._browse(k))
            row.addWidget(b)
            f.addRow(label, row)
        ol.addLayout(f)
        note = QLabel("The report's tables are also written as CSV beside it (<i>report</i>_intrinsic.csv, "
                      "_extrinsic_px.csv, …). The rig file carries the ROI and the calibration's provenance.")
        note.setWordWrap(True)
        note.setStyleSheet("color: #444444;")
        ol.addWidget(note)
        self.summary = QLabel()
        self.summary.setWordWrap(True)
        self.summary.setTextFormat(Qt.TextFormat.RichText)
        self.summary.setAlignment(Qt.AlignmentFlag.AlignTop)
        ol.addWidget(self.summary, 1)
        self.message = banner()
        ol.addWidget(self.message)
        self.save_btn = QPushButton("Save rig, report and tables")
        self.save_btn.setMinimumHeight(34)
        self.save_btn.clicked.connect(self.save)
        ol.addWidget(self.save_btn)
        lay.addWidget(o, 2)

        self._timer = QTimer(self)
        self._timer.setSingleShot(True)
        self._timer.setInterval(80)  # one redraw after spin-box ticks settle
        self._timer.timeout.connect(self._draw)
        self.model.session_changed.connect(self._session)
        self.model.calibration_changed.connect(self._calibration)
        self.model.report_changed.connect(self._summary)
        self.model.saved_changed.connect(lambda: self.saved(self.model.saved_paths))
        actions.busy_changed.connect(lambda b: self._buttons())

    # ------------------------------------------------------------------ state
    def _session(self) -> None:
        s = self.model.session
        self._roi_set = False
        self._depth_cache.clear()
        self.pose.blockSignals(True)
        self.pose.clear()
        if s is not None:
            for p in s.poses:
                if p.depth is not None:
                    self.pose.addItem(f"{p.name} (calibration board)", ("pose", p.name))
            folder = Path(s.folder)
            self.rig_path.setText(str(folder / "calibrated.rig.json"))
            self.report_path.setText(str(folder / "calibration_report.json"))
            self.pose.setCurrentIndex(self.pose.count() // 2)
        self.pose.blockSignals(False)
        self._set_roi(np.array([-0.5, -0.5, 0.2]), np.array([0.5, 0.5, 1.2]))
        self._buttons()

    def _calibration(self) -> None:
        cal = self.model.calibration
        if cal is not None and not self._roi_set:
            self._roi_set = True
            self._set_roi(cal.rig.roi_min, cal.rig.roi_max)
        self._rays = None
        self._buttons()
        self._summary()
        self._schedule()

    def _set_roi(self, lo, hi) -> None:
        for sp in self.spins.values():
            sp.blockSignals(True)
        for j, a in enumerate(AXES):
            self.spins[f"min_{a}"].setValue(float(lo[j]))
            self.spins[f"max_{a}"].setValue(float(hi[j]))
        for sp in self.spins.values():
            sp.blockSignals(False)
        self._schedule()

    def roi(self) -> tuple[np.ndarray, np.ndarray]:
        lo = np.array([self.spins[f"min_{a}"].value() for a in AXES])
        hi = np.array([self.spins[f"max_{a}"].value() for a in AXES])
        return lo, hi

    def set_roi(self, lo, hi) -> None:
        self._set_roi(np.asarray(lo, float), np.asarray(hi, float))

    def _buttons(self) -> None:
        lo, hi = self.roi()
        ok_roi = bool(np.all(lo < hi))
        self.save_btn.setEnabled(not self.actions.is_busy() and self.model.calibration_ready() and ok_roi)
        src = self.source()
        self.fit_btn.setEnabled(src is not None and src[0] == "plant" and self.model.calibration is not None)
        self.load_btn.setEnabled(self.model.calibration is not None and self.model.session is not None
                                 and self.model.session.depth_camera is not None)

    def _summary(self) -> None:
        from . import results

        cal, rep = self.model.calibration, self.model.report
        if cal is None:
            self.summary.setText("Not calibrated yet.")
            return
        lines = ["<b>Calibration summary</b>", "<table cellspacing=4>",
                 "<tr><th align=left>camera</th><th>fx</th><th>error px</th><th>norm.</th></tr>"]
        for r in results.intrinsic_rows(cal, rep if self.model.report_ready() else None):
            lines.append(f"<tr><td>{r['camera']}</td><td align=right>{r['fx']:.1f}</td>"
                         f"<td align=right>{r['px']:.3f}</td><td align=right>{r['normalized']:.3f}</td></tr>")
        lines.append("</table>")
        if rep is not None:
            ex = results.max_cell(results.table(rep, "extrinsic"))
            de = results.max_cell(results.table(rep, "depth") or {})
            if ex is not None:
                lines.append(f"Worst extrinsic error: {ex[2]:.3f} px ({ex[0]} → {ex[1]})")
            if de is not None:
                lines.append(f"<br>Worst depth error: {de[2]:.3f} px ({de[0]} → {de[1]})")
        if self.model.saved_paths:
            lines.append("<br><br><b>Saved:</b><br>" + "<br>".join(f"{k}: {v}" for k, v in self.model.saved_paths.items()))
        self.summary.setText("".join(lines))

    # ------------------------------------------------------------------ depth map
    def _schedule(self, *_) -> None:
        self._buttons()
        self._timer.start()

    def source(self) -> tuple[str, str] | None:
        """The shown depth map: ("pose", pose name) or ("plant", file path)."""
        d = self.pose.currentData()
        return tuple(d) if d else None

    def _source_changed(self, *_) -> None:
        self._schedule()

    def _browse_plant(self) -> None:
        f, _ = QFileDialog.getOpenFileName(self, "Depth map of a plant recording", "",
                                           "Depth maps and recordings (*.png *.tif *.tiff recording.json);;All files (*)")
        if f:
            self.load_plant_depth(Path(f))

    def load_plant_depth(self, path: Path) -> bool:
        """Show the depth map of a plant recording (an image, or a recording.json naming one)
        and fit the ROI to it. False (with a message) if it cannot be used."""
        import json

        path = Path(path)
        try:
            if path.suffix.lower() == ".json":
                meta = json.loads(path.read_text())
                if not isinstance(meta, dict) or not meta.get("depth"):
                    raise ValueError("the recording has no depth map")
                path = path.parent / str(meta["depth"])
            d = self._read_depth(path)
        except Exception as e:  # noqa: BLE001 -- any unreadable file is the same message
            set_banner(self.roi_msg, f"⚠ {path}: cannot use it as a depth map ({e})", error=True)
            return False
        cam = self.model.calibration.rig.depth() if self.model.calibration is not None else None
        if cam is not None and d.shape != (cam.height, cam.width):
            set_banner(self.roi_msg, f"⚠ {path}: the depth map is {d.shape[1]}x{d.shape[0]}, the depth camera "
                                     f"{cam.width}x{cam.height}", error=True)
            return False
        key = str(path)
        self._depth_cache[key] = d
        i = self.pose.findData(("plant", key))
        if i < 0:
            self.pose.addItem(f"plant: {path.parent.name}/{path.name}", ("plant", key))
            i = self.pose.count() - 1
        self.pose.setCurrentIndex(i)
        if self.message.text().startswith("Not saved: load a plant depth map"):
            set_banner(self.message, "")  # done
        if self.fit_roi():
            set_banner(self.roi_msg, f"ROI fitted to the plant depth map {path.name}: check it below, then save.")
        return True

    def _read_depth(self, path: Path) -> np.ndarray:
        from ...core.io.imageio import read_image

        d = read_image(path)
        if d.ndim == 3:
            d = d[:, :, 0]
        d = d.astype(np.float64) * self.model.session.depth_scale
        d[~(d > 0)] = np.nan
        return d

    def _depth_m(self, source: tuple[str, str]) -> np.ndarray | None:
        key = source[1] if source[0] == "plant" else f"pose:{source[1]}"
        if key in self._depth_cache:
            return self._depth_cache[key]
        if source[0] != "pose":
            return None
        try:
            d = self._read_depth(self.model.session.pose(source[1]).depth)
        except Exception:
            return None
        # keep the plant maps the user loaded, and one board pose
        self._depth_cache = {k: v for k, v in self._depth_cache.items() if not k.startswith("pose:")}
        self._depth_cache[key] = d
        return d

    def points(self, src: tuple[str, str] | None = None) -> tuple[np.ndarray, np.ndarray] | None:
        """Rig-frame points (h, w, 3) of the selected depth map (or of ``src``) and its depth
        (h, w), on a grid of every ``step``-th pixel (see PREVIEW_SIDE)."""
        cal, s = self.model.calibration, self.model.session
        src = self.source() if src is None else src
        if cal is None or s is None or src is None or cal.rig.depth_camera is None:
            return None
        d = self._depth_m(src)
        if d is None:
            return None
        cam = cal.rig.depth()
        if d.shape != (cam.height, cam.width):
            return None
        # a preview grid of at most ~PREVIEW_SIDE pixels a side: undistorting every pixel of the
        # depth camera on the GUI thread took longer than a frame
        step = max(1, int(np.ceil(max(cam.width, cam.height) / PREVIEW_SIDE)))
        if self._rays is None or self._rays[0] is not cal or self._rays[1] != step:
            v, u = np.mgrid[0:cam.height:step, 0:cam.width:step]
            self._rays = (cal, step, u.shape, cam.rays_cam(np.c_[u.ravel(), v.ravel()].astype(np.float64)))
        shape = self._rays[2]
        d = np.ascontiguousarray(d[::step, ::step])
        X_cam = self._rays[3] * d.reshape(-1, 1)  # depth maps hold z along the optical axis
        X = cam.to_rig(X_cam).reshape(shape[0], shape[1], 3)
        return X, d

    def _draw(self) -> None:
        if not self.isVisible():
            return  # drawn when shown (showEvent)
        lo, hi = self.roi()
        if not np.all(lo < hi):
            set_banner(self.roi_msg, "⚠ ROI min must be below max in x, y and z", error=True)
        elif "min must be below" in self.roi_msg.text():
            set_banner(self.roi_msg, "")
        if self.model.session is not None and self.model.session.depth_camera is None:
            self.image.setText("This rig has no depth camera: the ROI is stored in the rig file, "
                               "but there is no depth map to show it on.")
            return
        res = self.points()
        if res is None:
            self.image.setText("The depth map is shown once the rig is calibrated.")
            return
        X, d = res
        finite = np.isfinite(d)
        if not finite.any():
            self.image.setText("the depth map is empty")
            return
        lo_d, hi_d = np.nanpercentile(d, [1, 99])
        norm = np.clip((d - lo_d) / max(hi_d - lo_d, 1e-6), 0, 1)
        norm = np.nan_to_num(norm, nan=0.0)
        # grey, near = light: red, blue, yellow and cyan are reserved for the overlays (legend)
        grey = 230.0 - 170.0 * norm
        rgb = np.repeat(grey[:, :, None], 3, axis=2).astype(np.float32)
        with np.errstate(invalid="ignore"):
            inside = finite & np.all((X >= lo) & (X <= hi), axis=2)
            below = finite & (X[:, :, 2] > hi[2])
        outside = finite & ~inside & ~below
        rgb[outside] = 0.35 * rgb[outside] + 0.65 * np.array([200, 0, 0])
        rgb[below] = 0.35 * rgb[below] + 0.65 * np.array([20, 90, 255])
        rgb[~finite] = (40, 40, 40)
        # the ground plane's trace: the boundary between "above" and "below" ground
        mask = (np.nan_to_num(X[:, :, 2], nan=-1e9) > hi[2]).astype(np.uint8)
        edge = cv2.morphologyEx(mask, cv2.MORPH_GRADIENT, np.ones((3, 3), np.uint8)) > 0
        rgb[edge & finite] = (0, 220, 220)
        img = np.clip(rgb, 0, 255).astype(np.uint8)
        self.preview_rgb, self.preview_inside, self.preview_outside = img, inside, outside
        self.inside_fraction = float(inside.sum() / max(finite.sum(), 1))
        self._roi_banner(X, lo, hi)
        pm = qpixmap(img)
        self._overlay_roi(pm, lo, hi, self._rays[1])
        sz = self.image.size()
        self.image.setPixmap(pm.scaled(max(sz.width() - 4, 50), max(sz.height() - 4, 50),
                                       Qt.AspectRatioMode.KeepAspectRatio, Qt.TransformationMode.SmoothTransformation))
        self.image.setToolTip(f"{100 * self.inside_fraction:.0f} % of the measured pixels inside the ROI")

    def _overlay_roi(self, pm, lo: np.ndarray, hi: np.ndarray, step: int = 1) -> None:
        """Draw the ROI box (yellow) and a 10 cm grid on its ground face z = max z (cyan), projected
        through the calibrated depth camera, so they show even where the depth map is empty."""
        from PySide6.QtCore import QPointF
        from PySide6.QtGui import QColor, QPainter, QPen

        cam = self.model.calibration.rig.depth()
        p = QPainter(pm)
        p.setRenderHint(QPainter.RenderHint.Antialiasing)
        p.scale(1.0 / step, 1.0 / step)  # projected pixels are full-resolution; the preview every step-th

        def polyline(a, b, pen) -> None:
            X = np.linspace(a, b, 60)
            uv, z = cam.project(X)
            ok = np.isfinite(uv).all(axis=1) & (z > 0)
            p.setPen(pen)
            for i in range(len(X) - 1):
                if ok[i] and ok[i + 1]:
                    p.drawLine(QPointF(*uv[i]), QPointF(*uv[i + 1]))

        grid = QPen(QColor(0, 220, 220, 170), 1.0)
        grid.setCosmetic(True)
        step = 0.1
        for x in np.arange(np.ceil(lo[0] / step) * step, hi[0] + 1e-9, step):
            polyline([x, lo[1], hi[2]], [x, hi[1], hi[2]], grid)
        for y in np.arange(np.ceil(lo[1] / step) * step, hi[1] + 1e-9, step):
            polyline([lo[0], y, hi[2]], [hi[0], y, hi[2]], grid)
        box = QPen(QColor(255, 220, 0, 230), 2.0)
        box.setCosmetic(True)
        c = np.array([[x, y, z] for z in (lo[2], hi[2]) for y in (lo[1], hi[1]) for x in (lo[0], hi[0])])
        for i, j in ((0, 1), (2, 3), (4, 5), (6, 7), (0, 2), (1, 3), (4, 6), (5, 7), (0, 4), (1, 5), (2, 6), (3, 7)):
            polyline(c[i], c[j], box)
        p.resetTransform()
        p.setPen(QColor(0, 230, 230))
        f = p.font()
        f.setPixelSize(max(8, pm.height() // 32))  # the preview is shown scaled up
        f.setBold(True)
        p.setFont(f)
        p.drawText(4, pm.height() - 4, f"ground plane z = {hi[2]:.2f} m")
        p.end()

    def _roi_banner(self, X: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> None:
        """Say what the ROI does to the shown depth map (cuts the plant, takes in the ground);
        ask for a plant's depth map while none is loaded."""
        from ...core.geometry.roi import CUT_WARN_FRACTION, cut_fraction, ground_warning

        if not np.all(lo < hi):
            return
        src = self.source()
        msgs = []
        if src is not None and src[0] == "plant":
            frac, n = cut_fraction(X, lo, hi)  # the same test as registration's warning
            if n >= 100 and frac > CUT_WARN_FRACTION:
                msgs.append(f"⚠ The ROI leaves out {100 * frac:.0f} % of the plant's top (the nearest depth mid-view): "
                            "the registration would keep only part of the plant. 'Fit ROI to the plant' or widen it.")
        if src is not None:
            g = ground_warning(X, lo, hi, advice=False)  # the same test as registration's warning
            if g:
                msgs.append(f"⚠ In this depth map, {g}. Lower max z to a few centimetres in front of the ground.")
        if not self.plant_loaded():
            msgs.append("Set the ROI from a plant: 'Load plant depth map…' (a recording of a plant "
                        "with this rig). The board poses only show where the board was.")
        if msgs:
            set_banner(self.roi_msg, " ".join(msgs), error=any(m.startswith("⚠") for m in msgs))
        elif "⚠" in self.roi_msg.text() or self.roi_msg.text().startswith("Set the ROI from a plant"):
            set_banner(self.roi_msg, "")  # what it said no longer holds; "ROI fitted to ..." stays

    def plant_loaded(self) -> bool:
        """Whether a plant's depth map has been loaded (the only thing that can check an ROI)."""
        return any(self.pose.itemData(i)[0] == "plant" for i in range(self.pose.count()))

    def roi_question(self, lo: np.ndarray, hi: np.ndarray) -> str | None:
        """Why saving the ROI ``lo``, ``hi`` (3,) needs a confirmation, in words: no plant's depth
        map checked it, or a loaded plant's depth map shows it cutting the plant or taking in the
        ground (the tests registration warns with). None: nothing to ask (or no depth camera)."""
        from ...core.geometry.roi import cut_warning, ground_warning

        s = self.model.session
        if s is None or s.depth_camera is None:
            return None
        box = (f"    x {lo[0]:.2f} … {hi[0]:.2f} m,  y {lo[1]:.2f} … {hi[1]:.2f} m,  z {lo[2]:.2f} … {hi[2]:.2f} m "
               f"(ground plane at z = {hi[2]:.2f} m)")
        if not self.plant_loaded():
            return ("No plant depth map was loaded, so this region of interest was not checked against a plant:\n"
                    f"{box}\nRegistration takes everything measured inside it as the plant: with the ground plane "
                    "in or behind the ground, table or background, that surface is registered as plant.")
        found = []
        for i in range(self.pose.count()):
            src = self.pose.itemData(i)
            res = self.points(tuple(src)) if src[0] == "plant" else None
            if res is not None:
                found += [f"{Path(src[1]).name}: {w}" for w in (cut_warning(res[0], lo, hi, advice=False),
                                                                ground_warning(res[0], lo, hi, advice=False)) if w]
        if not found:
            return None
        return "This region of interest does not fit the plant's depth map:\n" + box + "\n\n" + "\n".join(found)

    def fit_roi(self) -> bool:
        """Fit the ROI to the shown plant depth map (core.roi.fit_roi); False for a board pose."""
        from ...core.geometry.roi import fit_roi

        src = self.source()
        res = self.points()
        if res is None or src is None or src[0] != "plant":
            return False
        try:
            lo, hi = fit_roi(res[0])
        except ValueError as e:
            set_banner(self.roi_msg, f"⚠ {e}", error=True)
            return False
        self._set_roi(np.round(lo, 3), np.round(hi, 3))
        return True

    def resizeEvent(self, event) -> None:  # noqa: N802
        super().resizeEvent(event)
        self._timer.start()

    def showEvent(self, event) -> None:  # noqa: N802
        super().showEvent(event)
        self._summary()
        self._timer.start()

    # ------------------------------------------------------------------ saving
    def _browse(self, kind: str) -> None:
        edit = self.rig_path if kind == "rig" else self.report_path
        f, _ = QFileDialog.getSaveFileName(self, "Save " + kind, edit.text(), "JSON (*.json)")
        if f:
            edit.setText(f)
            self._confirmed.add(str(Path(f)))  # the file dialog asked about replacing it

    def _replaced_files(self, paths: list[Path]) -> list[Path]:
        """Existing files among ``paths`` that saving would replace and the user has not agreed
        to replace (chosen in the file dialog, or written by this wizard before)."""
        mine = {str(Path(v)) for k, v in self.model.saved_paths.items() if k in ("rig", "report")}
        return [p for p in paths if p.exists() and str(p) not in mine and str(p) not in self._confirmed]

    def save(self) -> None:
        lo, hi = self.roi()
        if not np.all(lo < hi):
            set_banner(self.message, "⚠ fix the ROI first (min below max)", error=True)
            return
        if not self.rig_path.text().strip():
            set_banner(self.message, "⚠ choose a rig file", error=True)
            return
        set_banner(self.message, "")
        question = self.roi_question(lo, hi)
        if question is not None:  # an ROI nobody checked against a plant takes in the ground unseen
            box = QMessageBox(QMessageBox.Icon.Warning, "Check the region of interest", question,
                              QMessageBox.StandardButton.NoButton, self)
            load = box.addButton("Load plant depth map…", QMessageBox.ButtonRole.AcceptRole)
            keep = box.addButton("Save this ROI anyway", QMessageBox.ButtonRole.DestructiveRole)
            box.addButton("Cancel", QMessageBox.ButtonRole.RejectRole)
            box.setDefaultButton(load)
            box.exec()
            if box.clickedButton() is load:
                self._browse_plant()
                return
            if box.clickedButton() is not keep:
                set_banner(self.message, "Not saved: load a plant depth map to set the ROI, or save again.")
                return
        rep = self.report_path.text().strip()
        rig_path, rep_path = Path(self.rig_path.text().strip()), (Path(rep) if rep else None)
        # a rig file is a calibration someone may still use: never replace one silently
        existing = self._replaced_files([p for p in (rig_path, rep_path) if p is not None])
        if existing:
            ans = QMessageBox.question(
                self, "Replace files?",
                "These files exist and would be replaced:\n" + "\n".join(str(p) for p in existing)
                + "\n\nReplace them?",
                QMessageBox.StandardButton.Yes | QMessageBox.StandardButton.No, QMessageBox.StandardButton.No)
            if ans != QMessageBox.StandardButton.Yes:
                set_banner(self.message, "Not saved: choose other file names, or save again and confirm.")
                return
            self._confirmed.update(str(p) for p in existing)
        # a calibration beyond the uncertainty limits is saved only on explicit confirmation, and
        # then flagged in the rig's provenance and the report (as `plantreg calibrate --accept-uncertain`)
        cal = self.model.calibration
        problems = results.uncertainty_problems(cal)
        if problems and list(getattr(cal, "accepted_uncertain", [])) != problems:
            box = QMessageBox(QMessageBox.Icon.Warning, "Calibration too uncertain",
                              "The board views do not determine this calibration well enough:\n\n• "
                              + "\n• ".join(problems)
                              + "\n\nBetter: go back, record the board views named above and recalibrate. "
                                "Save it anyway? The rig file and the report will say it was kept although "
                                "uncertain.", QMessageBox.StandardButton.NoButton, self)
            keep = box.addButton("Save anyway (flagged as uncertain)", QMessageBox.ButtonRole.AcceptRole)
            box.addButton("Don't save", QMessageBox.ButtonRole.RejectRole)
            box.setDefaultButton(box.buttons()[-1])
            box.exec()
            if box.clickedButton() is not keep:
                set_banner(self.message, "Not saved: the calibration is too uncertain (see the Intrinsics and "
                                         "Extrinsics pages for where to add views).", error=True)
                return
            cal.accepted_uncertain = list(problems)
            if self.model.report is not None:
                self.model.report.accepted_uncertain = list(problems)
        self.actions.save_outputs(rig_path, rep_path, lo, hi)

    def saved(self, paths: dict[str, str]) -> None:
        set_banner(self.message, "Saved " + ", ".join(paths.values()))
        self.message.setStyleSheet("QLabel#banner { background: #d4edda; color: #155724; border: 1px solid #a3d3b0;"
                                   " padding: 4px; border-radius: 3px; }")
        self._summary()
