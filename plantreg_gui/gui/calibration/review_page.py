"""Page 3: corner review — corners drawn in order, accept/reject, re-detect, coverage per camera."""

from __future__ import annotations

from collections import OrderedDict

import numpy as np
from PySide6.QtCore import Qt
from PySide6.QtGui import QColor, QKeySequence, QPainter, QPen, QShortcut
from PySide6.QtWidgets import (QCheckBox, QComboBox, QFormLayout, QGroupBox, QHBoxLayout, QLabel,
                               QListWidget, QListWidgetItem, QPushButton, QSizePolicy, QSplitter,
                               QVBoxLayout, QWidget)

from ..workers import Jobs
from ...core.calibration.coverage import coverage_image, coverage_map, empty_regions
from ...core.camera.modality import inverted_board
from .page import WizardPage
from .image_view import ImageView
from .widgets import banner, qpixmap, set_banner, to_display

STATUS_MARK = {"found": "✔", "failed": "✖", "missing": "—", None: "…"}
REJECTED_MARK = "⊘"


class ReviewPage(WizardPage):
    title = "Corner review"

    def __init__(self, model, actions) -> None:
        super().__init__(model, actions)
        self.current: tuple[str, str] | None = None
        self._cache: OrderedDict = OrderedDict()
        lay = QHBoxLayout(self)
        split = QSplitter(Qt.Orientation.Horizontal)
        lay.addWidget(split)

        # --- image list
        left = QWidget()
        ll = QVBoxLayout(left)
        ll.setContentsMargins(0, 0, 0, 0)
        self.cam_filter = QComboBox()
        self.cam_filter.currentIndexChanged.connect(self._fill_list)
        ll.addWidget(self.cam_filter)
        self.list = QListWidget()
        self.list.currentItemChanged.connect(self._on_item)
        ll.addWidget(self.list, 1)
        split.addWidget(left)

        # --- image
        mid = QWidget()
        ml = QVBoxLayout(mid)
        ml.setContentsMargins(0, 0, 0, 0)
        self.caption = QLabel()
        self.caption.setWordWrap(True)
        ml.addWidget(self.caption)
        self.view = ImageView()
        ml.addWidget(self.view, 1)
        legend = QLabel("Corner order: <span style='color:#d00000'><b>ring + 0 = first corner</b></span>, "
                        "red arrow = along the first row, colour runs red → yellow → green → blue to the last "
                        "corner; dotted = wrap to the next row. The same board corner must carry the ring "
                        "in every camera. Wheel zooms, drag pans, double-click fits.")
        legend.setWordWrap(True)
        legend.setStyleSheet("color: #444444;")
        ml.addWidget(legend)
        # once calibrated: residual vectors (scale stated) and the image undistorted by the model
        rb = QHBoxLayout()
        self.undistort = QCheckBox("Show undistorted")
        self.undistort.setToolTip("The image and its corners undistorted with this camera's calibrated lens model "
                                  "(cv2.undistort, same camera matrix): the board's edges must come out straight")
        self.undistort.toggled.connect(self.model.set_review_undistorted)
        rb.addWidget(self.undistort)
        self.resid_legend = QLabel()
        self.resid_legend.setWordWrap(True)
        self.resid_legend.setStyleSheet("color: #444444;")
        rb.addWidget(self.resid_legend, 1)
        ml.addLayout(rb)
        split.addWidget(mid)
        self._undistorted: OrderedDict = OrderedDict()  # (key, K bytes) -> undistorted display image
        self.jobs = Jobs(self)  # cv2.undistort off the GUI thread

        # --- controls + coverage
        right = QWidget()
        rl = QVBoxLayout(right)
        rl.setContentsMargins(0, 0, 0, 0)
        ag = QGroupBox("All images")
        af = QFormLayout(ag)
        self.detector = QComboBox()
        self.detector.addItem("automatic (recommended)", "auto")
        self.detector.addItem("OpenCV classic (11×11 sub-pixel)", "classic")
        self.detector.setToolTip("Automatic (findChessboardCornersSB, sub-pixel window sized to the squares) is "
                                 "more accurate; classic reproduces OpenCV's published figures but its 11×11 "
                                 "window misplaces corners where squares are smaller than ~24 px.")
        self.detector.currentIndexChanged.connect(self._detector_chosen)
        af.addRow("Corner detector:", self.detector)
        rl.addWidget(ag)
        g = QGroupBox("This image")
        gl = QVBoxLayout(g)
        self.use = QCheckBox("Use this view in the calibration")
        self.use.toggled.connect(self._toggle_use)
        gl.addWidget(self.use)
        hb = QHBoxLayout()
        self.accept_btn = QPushButton("Accept (A)")
        self.reject_btn = QPushButton("Reject (R)")
        for key, used in (("A", True), ("R", False)):
            sc = QShortcut(QKeySequence(key), self)
            sc.setContext(Qt.ShortcutContext.WidgetWithChildrenShortcut)
            sc.activated.connect(lambda u=used: self.set_used(u))
        self.accept_btn.clicked.connect(lambda: self.set_used(True))
        self.reject_btn.clicked.connect(lambda: self.set_used(False))
        hb.addWidget(self.accept_btn)
        hb.addWidget(self.reject_btn)
        gl.addLayout(hb)
        f = QFormLayout()
        self.polarity = QComboBox()
        self.polarity.addItems(["automatic (by modality)", "normal (dark squares dark)", "inverted (heated board)"])
        self.enhance = QCheckBox("contrast enhancement (CLAHE)")
        f.addRow("Polarity:", self.polarity)
        f.addRow(self.enhance)
        gl.addLayout(f)
        self.redetect_btn = QPushButton("Re-detect with these options")
        self.redetect_btn.clicked.connect(self._redetect)
        gl.addWidget(self.redetect_btn)
        self.info = banner()
        gl.addWidget(self.info)
        rl.addWidget(g)

        cg = QGroupBox("Coverage (where the board has been)")
        cl = QVBoxLayout(cg)
        self.cov_cam = QComboBox()
        self.cov_cam.currentIndexChanged.connect(self._update_coverage)
        cl.addWidget(self.cov_cam)
        self.cov_img = QLabel()
        self.cov_img.setAlignment(Qt.AlignmentFlag.AlignCenter)
        self.cov_img.setMinimumHeight(150)
        self.cov_img.setSizePolicy(QSizePolicy.Policy.Ignored, QSizePolicy.Policy.Ignored)
        cl.addWidget(self.cov_img, 1)
        self.cov_text = QLabel()
        self.cov_text.setWordWrap(True)
        cl.addWidget(self.cov_text)
        rl.addWidget(cg, 1)
        split.addWidget(right)
        split.setSizes([220, 800, 360])
        split.setStretchFactor(1, 1)

        self.model.session_changed.connect(self._session)
        self.model.detection_changed.connect(self._detection)
        self.model.review_changed.connect(self._review)
        self.model.board_hint_changed.connect(self._show_controls)
        self.model.calibration_changed.connect(self._relabel)
        self.model.calibration_changed.connect(self._calibration)
        self.model.review_display_changed.connect(self._show)
        self.model.view_selected.connect(lambda key: self.select(key[1], key[0]))
        self.model.poses_changed.connect(self._fill_list)
        actions.busy_changed.connect(self._busy)

    def _busy(self, busy: bool) -> None:
        self.redetect_btn.setEnabled(not busy and self.current is not None)
        self.detector.setEnabled(not busy and self.model.session is not None)

    # ------------------------------------------------------------------ lists
    def _session(self) -> None:
        self._cache.clear()
        self.current = None
        s = self.model.session
        self.cam_filter.blockSignals(True)
        self.cam_filter.clear()
        self.cam_filter.addItem("all cameras")
        self.cov_cam.blockSignals(True)
        self.cov_cam.clear()
        if s is not None:
            self.cam_filter.addItems(s.camera_names)
            self.cov_cam.addItems(s.camera_names)
        self.cam_filter.blockSignals(False)
        self.cov_cam.blockSignals(False)
        self.detector.blockSignals(True)
        self.detector.setCurrentIndex(max(0, self.detector.findData(self.model.detector())))
        self.detector.blockSignals(False)
        self._fill_list()
        self.view.clear("no image selected")
        if self.list.count():
            self.list.setCurrentRow(0)  # something to look at, also when the page is already shown

    def _fill_list(self) -> None:
        s = self.model.session
        keep = self.current
        self.list.blockSignals(True)
        self.list.clear()
        if s is not None:
            cam = self.cam_filter.currentText()
            for p in s.poses:
                for c in s.camera_names:
                    if cam not in ("", "all cameras") and c != cam:
                        continue
                    it = QListWidgetItem()
                    it.setData(Qt.ItemDataRole.UserRole, (p.name, c))
                    self.list.addItem(it)
                    self._label(it)
        self.list.blockSignals(False)
        if keep is not None:
            self.select(keep[1], keep[0])

    def _label(self, it: QListWidgetItem) -> None:
        key = it.data(Qt.ItemDataRole.UserRole)
        d = self.model.detections.get(key)
        st = getattr(d, "status", None)
        ex = key in self.model.excluded
        weak = self._weak.get(key)
        mark = REJECTED_MARK if ex else STATUS_MARK.get(st, "?")  # a rejected view never shows a green tick
        it.setText(f"{mark} {key[0]} · {key[1]}" + ("  (rejected)" if ex else "")
                   + (f"  (weak {weak:.2f} px)" if weak is not None and not ex else ""))
        col = {"found": "#1e7e34", "failed": "#b02a37", "missing": "#6c757d"}.get(st, "#000000")
        it.setForeground(QColor("#999999" if ex else ("#c65d00" if weak is not None else col)))
        if d is not None and d.reason:
            it.setToolTip(d.reason)
        elif d is not None and getattr(d, "variant_text", ""):
            it.setToolTip(f"found on: {d.variant_text}")

    @property
    def _weak(self) -> dict:
        cal = self.model.calibration
        if cal is None:
            return {}
        return {(p, c): e for c, ci in cal.intrinsics.items() for p, e, _r in ci.weak_views}

    def _relabel(self) -> None:
        for i in range(self.list.count()):
            self._label(self.list.item(i))

    def _detection(self, key) -> None:
        for i in range(self.list.count()):
            it = self.list.item(i)
            if key is None or it.data(Qt.ItemDataRole.UserRole) == key:
                self._label(it)
        if key is None or key == self.current:
            self._show()
        if self.isVisible():
            self._update_coverage()

    def _review(self) -> None:
        self._relabel()
        self._show_controls()
        self._update_coverage()

    # ------------------------------------------------------------------ selection
    def select(self, camera: str, pose: str) -> bool:
        """Show image (pose, camera); returns False if the session has no such image."""
        key = (pose, camera)
        if self.cam_filter.currentText() not in ("all cameras", camera):
            self.cam_filter.setCurrentText(camera)
        for i in range(self.list.count()):
            it = self.list.item(i)
            if it.data(Qt.ItemDataRole.UserRole) == key:
                self.list.setCurrentItem(it)
                self.list.scrollToItem(it)
                self.current = key
                self._show()
                if self.cov_cam.currentText() != camera:
                    self.cov_cam.setCurrentText(camera)
                return True
        return False

    def _on_item(self, it, _prev=None) -> None:
        if it is None:
            return
        self.current = it.data(Qt.ItemDataRole.UserRole)
        self._show()
        if self.cov_cam.currentText() != self.current[1]:
            self.cov_cam.setCurrentText(self.current[1])

    def _image(self, key) -> np.ndarray | None:
        from ...core.io.imageio import read_image

        if key in self._cache:
            self._cache.move_to_end(key)
            return self._cache[key]
        s = self.model.session
        path = s.pose(key[0]).images.get(key[1]) if s is not None else None
        if path is None:
            return None
        try:
            img = to_display(read_image(path))
        except Exception:
            return None
        self._cache[key] = img
        while len(self._cache) > 12:  # a few full images, not the whole session
            self._cache.popitem(last=False)
        return img

    def _show(self) -> None:
        key = self.current
        s = self.model.session
        if key is None or s is None:
            return
        img = self._image(key)
        d = self.model.detections.get(key)
        if img is None:
            self.view.clear(f"{key[0]} / {key[1]}: no image" if d is None or not d.reason else d.reason)
        else:
            self._show_image(key, img, d)
        st = getattr(d, "status", None)
        cap = f"<b>{key[0]} · {key[1]}</b> ({s.cameras.get(key[1], '')}) — "
        if d is None:
            cap += "not detected yet"
        elif st == "found":
            cap += f"{len(d.corners)} corners found" + (" (polarity inverted)" if getattr(d, "inverted", False) else "")
            how = getattr(d, "variant_text", "")
            if how:
                cap += f"<br><span style='color:#555555'>found on: {how}</span>"
        else:
            cap += f"{st}: {d.reason}"
        self.caption.setText(cap)
        self._show_controls()

    def _calibrated(self, camera: str):
        """The camera's calibrated intrinsics (CameraCalibration), None before calibration."""
        cal = self.model.calibration
        return cal.intrinsics.get(camera) if cal is not None and self.model.calibration_ready() else None

    def _show_image(self, key, img: np.ndarray, d) -> None:
        """The image (undistorted when chosen and ready), its corners in order and, once the
        camera is calibrated, each corner's residual vector with the scale it is drawn at."""
        from ...core.calibration.residuals import drawing_scale, undistort_points, view_residuals

        s = self.model.session
        cc = self._calibrated(key[1])
        self.undistort.setEnabled(cc is not None)
        und = None
        if cc is not None and self.model.review_undistorted:
            und = self._undistorted.get((key, cc.K.tobytes() + cc.dist.tobytes()))
            if und is None:
                self._start_undistort(key, img, cc)
        self.view.set_image(img if und is None else und)
        self.shown_undistorted = und is not None
        found = d is not None and d.status == "found" and d.corners is not None
        corners = None
        if found:
            corners = d.corners if und is None else undistort_points(d.corners, cc.K, cc.dist)
            self.view.set_corners(corners, s.board.columns, getattr(d, "ids", None) if s.board.type == "charuco" else None)
            self.view.focus_corners(corners)
        res = view_residuals(self.model.calibration, d, s.board) if found and cc is not None else None
        if res is None:
            self.view.set_residuals(None, None, 1.0)
            self.resid_legend.setText("Residual vectors and the undistorted view: once the camera is calibrated (page 4)."
                                      if cc is None else "")
            self.residual_scale = None
            return
        c, r = res
        if und is not None:  # the same vectors in the undistorted image
            r = undistort_points(c + r, cc.K, cc.dist) - corners
            c = corners
        steps = np.linalg.norm(np.diff(c, axis=0), axis=1)
        scale = drawing_scale(r, float(np.median(steps)) if len(steps) else 10.0)
        self.view.set_residuals(c, r, scale)
        self.residual_scale = scale
        n = np.linalg.norm(r, axis=1)
        wait = " Undistorting…" if cc is not None and self.model.review_undistorted and und is None else ""
        self.resid_legend.setText(f"<span style='color:#c000c0'><b>Magenta</b></span>: residual vectors (reprojected − "
                                  f"detected corner) drawn <b>×{scale:g}</b> (1 px of error = {scale:g} px on the "
                                  f"image); mean {n.mean():.3f} px, max {n.max():.3f} px.{wait}")

    def _start_undistort(self, key, img: np.ndarray, cc) -> None:
        from ...core.calibration.residuals import undistort_image
        from ..workers import Worker

        tag = (key, cc.K.tobytes() + cc.dist.tobytes())
        if any(getattr(w, "tag", None) == tag for w in self.jobs):
            return
        for w in self.jobs:
            w.supersede()  # another image's: its result is dropped
        w = Worker(undistort_image, img, cc.K, cc.dist, parent=self)
        w.tag = tag
        self.jobs.start(w, "Undistorting the image", lambda out, t=tag: self._undistorted_done(t, out),
                        on_end=lambda w: w.deleteLater(), background=True)

    def _undistorted_done(self, tag, out: np.ndarray) -> None:
        self._undistorted[tag] = out
        while len(self._undistorted) > 6:
            self._undistorted.popitem(last=False)
        if self.current == tag[0] and self.model.review_undistorted:
            self._show()

    def undistort_busy(self) -> bool:
        return bool(self.jobs)

    def shutdown(self) -> None:
        self.jobs.wait_all()

    def _calibration(self) -> None:
        self._undistorted.clear()
        if self.current is not None and self.isVisible():
            self._show()

    def _show_controls(self) -> None:
        key = self.current
        if key is None or self.model.session is None:
            return
        d = self.model.detections.get(key)
        self.use.blockSignals(True)
        self.use.setChecked(key not in self.model.excluded)
        self.use.setEnabled(d is not None and d.status == "found")
        self.use.blockSignals(False)
        opts = self.model.options().get(key)
        inv = getattr(opts, "invert", None)
        self.polarity.setCurrentIndex(0 if inv is None else (2 if inv else 1))
        self.enhance.setChecked(bool(getattr(opts, "enhance", False)))
        self.redetect_btn.setEnabled(not self.actions.is_busy() and key[1] in self.model.session.pose(key[0]).images)
        if d is not None and d.status == "failed":
            if self.model.board_hint is not None:  # every image fails alike: the size, not the image
                advice = f"{self.model.board_hint_text()} Set it on page 1 (or with the button on page 2)."
            elif inverted_board(self.model.session.cameras.get(key[1])):  # a heated board: thermal cameras
                advice = "For a thermal image try the inverted polarity and contrast enhancement, then Re-detect."
            else:
                advice = "Try contrast enhancement for a faint or unevenly lit board, then Re-detect."
            set_banner(self.info, f"Detection failed: {d.reason}. {advice}")
        elif key in self.model.excluded:
            set_banner(self.info, "Rejected: this view is not used in the calibration.")
        else:
            set_banner(self.info, "")

    # ------------------------------------------------------------------ actions
    def _toggle_use(self, on: bool) -> None:
        self.set_used(on)

    def set_used(self, used: bool) -> None:
        if self.current is None:
            return
        self.model.set_excluded_many({self.current}, not used)

    def current_options(self):

        from ...core.calibration import DetectOptions
        inv = {0: None, 1: False, 2: True}[self.polarity.currentIndex()]
        return DetectOptions(invert=inv, enhance=self.enhance.isChecked(), detector=self.model.detector())

    def _detector_chosen(self, _index: int) -> None:
        self.actions.set_detector(self.detector.currentData())
        # refused while busy or without a session: show what is in use
        self.detector.blockSignals(True)
        self.detector.setCurrentIndex(max(0, self.detector.findData(self.model.detector())))
        self.detector.blockSignals(False)

    def _redetect(self) -> None:
        if self.current is not None:
            self.actions.redetect(self.current, self.current_options())

    # ------------------------------------------------------------------ coverage
    def _update_coverage(self) -> None:
        cam = self.cov_cam.currentText()
        if not cam:
            self.cov_img.clear()
            self.cov_text.setText("")
            return
        res = coverage_map(self.model.detections, cam, self.model.excluded)
        if res is None:
            self.cov_img.setText(f"no board found for {cam} yet")
            self.cov_text.setText("")
            self.coverage_fraction = 0.0
            return
        acc, (W, H) = res
        rgb = coverage_image(acc)
        pm = qpixmap(rgb)
        p = QPainter(pm)
        p.setPen(QPen(QColor(255, 255, 255, 140), 1, Qt.PenStyle.DashLine))
        for k in (1, 2):
            p.drawLine(k * pm.width() // 3, 0, k * pm.width() // 3, pm.height())
            p.drawLine(0, k * pm.height() // 3, pm.width(), k * pm.height() // 3)
        p.end()
        target = self.cov_img.size()
        self.cov_img.setPixmap(pm.scaled(max(target.width() - 4, 50), max(target.height() - 4, 50),
                                         Qt.AspectRatioMode.KeepAspectRatio, Qt.TransformationMode.SmoothTransformation))
        self.coverage_fraction = float((acc > 0).mean())
        empty = empty_regions(acc)
        n = int(acc.max())
        txt = (f"{cam} ({W} × {H}): {100 * self.coverage_fraction:.0f} % of the image seen by the board, "
               f"up to {n} views per pixel (yellow). ")
        txt += (f"<b style='color:#b02a37'>Still empty: {', '.join(empty)}</b> — put the board there."
                if empty else "Every region of the image has been covered.")
        self.cov_text.setText(txt)

    def showEvent(self, event) -> None:  # noqa: N802
        super().showEvent(event)
        self._relabel()
        if self.current is None and self.list.count():
            self.list.setCurrentRow(0)
        self._update_coverage()

    def resizeEvent(self, event) -> None:  # noqa: N802
        super().resizeEvent(event)
        if self.isVisible():
            self._update_coverage()
