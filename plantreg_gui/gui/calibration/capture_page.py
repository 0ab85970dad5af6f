"""Page 2: capture list — poses x cameras with thumbnails and detection status."""

from __future__ import annotations

from pathlib import Path

from PySide6.QtCore import QSize, Qt
from PySide6.QtGui import QColor, QIcon
from PySide6.QtWidgets import (QAbstractItemView, QFileDialog, QHBoxLayout, QHeaderView, QLabel,
                               QMessageBox, QPushButton, QTableWidget, QTableWidgetItem, QVBoxLayout)

from .page import WizardPage
from .widgets import banner, qpixmap, set_banner

STATUS_COLOURS = {"found": "#d4edda", "failed": "#f8d7da", "missing": "#e2e3e5", None: "#ffffff"}
#: how a board was found, when not on the plain image (the variants of core/calibration/detect.py)
VARIANT_SHORT = {"flat": "background removed", "flat-fine": "background removed", "fine-2x": "background removed", "clahe": "contrast enhanced",
                 "thorough": "exhaustive search", "full-res": "full resolution"}
STATUS_TEXT = {"found": "✔ found", "failed": "✖ failed", "missing": "— missing", None: "… not detected yet"}


class CaptureTable(QTableWidget):
    """The poses x cameras table; accepts pose folders dropped onto it."""

    def __init__(self, page) -> None:
        super().__init__(0, 0)
        self.page = page
        self.setAcceptDrops(True)
        self.viewport().setAcceptDrops(True)
        self.setDragDropMode(QAbstractItemView.DragDropMode.DropOnly)
        self.setEditTriggers(QAbstractItemView.EditTrigger.NoEditTriggers)
        self.setSelectionBehavior(QAbstractItemView.SelectionBehavior.SelectRows)
        self.setIconSize(QSize(112, 84))
        self.horizontalHeader().setSectionResizeMode(QHeaderView.ResizeMode.Stretch)
        self.verticalHeader().setDefaultSectionSize(92)

    def _dirs(self, event) -> list[Path]:
        md = event.mimeData()
        if not md.hasUrls():
            return []
        return [Path(u.toLocalFile()) for u in md.urls() if u.isLocalFile() and Path(u.toLocalFile()).is_dir()]

    def dragEnterEvent(self, event) -> None:  # noqa: N802
        if self._dirs(event):
            event.acceptProposedAction()
        else:
            event.ignore()

    def dragMoveEvent(self, event) -> None:  # noqa: N802
        if self._dirs(event):
            event.acceptProposedAction()
        else:
            event.ignore()

    def dropEvent(self, event) -> None:  # noqa: N802
        dirs = self._dirs(event)
        if dirs:
            event.acceptProposedAction()
            self.page.add_folders(dirs)
        else:
            event.ignore()


class CapturePage(WizardPage):
    title = "Capture list"

    def __init__(self, model, actions) -> None:
        super().__init__(model, actions)
        lay = QVBoxLayout(self)
        self.summary = QLabel()
        self.summary.setWordWrap(True)
        lay.addWidget(self.summary)
        self.table = CaptureTable(self)
        self.table.cellDoubleClicked.connect(self._open_review)
        lay.addWidget(self.table, 1)
        mb = QHBoxLayout()
        self.message = banner()
        mb.addWidget(self.message, 1)
        # a wrong board size fails every image: the size that was found, one click away
        self.use_hint_btn = QPushButton()
        self.use_hint_btn.hide()
        self.use_hint_btn.clicked.connect(self._use_hint)
        mb.addWidget(self.use_hint_btn)
        lay.addLayout(mb)
        hb = QHBoxLayout()
        self.add_btn = QPushButton("Add pose folder…")
        self.add_btn.setToolTip("Copy a folder of images named after the cameras into the session "
                                "(or drop folders onto the table)")
        self.remove_btn = QPushButton("Remove selected poses")
        self.detect_btn = QPushButton("Detect corners")
        self.add_btn.clicked.connect(self._add)
        self.remove_btn.clicked.connect(self._remove)
        self.detect_btn.clicked.connect(lambda: self.actions.run_detection(None))
        hint = QLabel("Drop pose folders here. Double-click an image to review its corners.")
        hint.setStyleSheet("color: #666666;")
        hb.addWidget(hint, 1)
        hb.addWidget(self.add_btn)
        hb.addWidget(self.remove_btn)
        hb.addWidget(self.detect_btn)
        lay.addLayout(hb)
        self.model.session_changed.connect(self.rebuild)
        self.model.poses_changed.connect(self.rebuild)
        self.model.detection_changed.connect(self.update_cell)
        self.model.review_changed.connect(self._update_all)
        self.model.board_hint_changed.connect(self._summary)
        actions.busy_changed.connect(self._busy)

    def _busy(self, busy: bool) -> None:
        for b in (self.add_btn, self.remove_btn, self.detect_btn):
            b.setEnabled(not busy and self.model.session is not None)

    # ------------------------------------------------------------------ table
    def rebuild(self) -> None:
        s = self.model.session
        self.table.clear()
        if s is None:
            self.table.setRowCount(0)
            self.table.setColumnCount(0)
            self._summary()
            return
        cams = s.camera_names
        self.table.setColumnCount(len(cams))
        self.table.setHorizontalHeaderLabels([f"{c} ({s.cameras[c]})" for c in cams])
        self.table.setRowCount(len(s.poses))
        self.table.setVerticalHeaderLabels([p.name for p in s.poses])
        for i, p in enumerate(s.poses):
            for j, c in enumerate(cams):
                self._set_cell(i, j, (p.name, c))
        self._summary()
        self._busy(self.actions.is_busy())

    def _update_all(self) -> None:
        s = self.model.session
        if s is None:
            return
        for i, p in enumerate(s.poses):
            for j, c in enumerate(s.camera_names):
                self._set_cell(i, j, (p.name, c))
        self._summary()

    def update_cell(self, key) -> None:
        s = self.model.session
        if s is None:
            return
        if key is None:
            self._update_all()
            return
        names = [p.name for p in s.poses]
        if key[0] not in names or key[1] not in s.camera_names:
            return
        self._set_cell(names.index(key[0]), s.camera_names.index(key[1]), key)
        self._summary()

    def _set_cell(self, row: int, col: int, key) -> None:
        det = self.model.detections.get(key)
        status = getattr(det, "status", None)
        excluded = key in self.model.excluded
        pose = self.model.session.pose(key[0])
        if status is None and key[1] not in pose.images:
            status = "missing"
        text = STATUS_TEXT.get(status, str(status))
        if excluded and status == "found":
            text = "⊘ rejected"  # found but excluded: no green tick
        if status == "found" and det.corners is not None:
            text += f" ({len(det.corners)})"
            if getattr(det, "variant", "") not in ("", "plain"):
                text += "\n" + VARIANT_SHORT.get(det.variant, det.variant)
        elif status == "failed" and det.reason:
            r = det.reason.split(" (")[0]
            text += "\n" + (r if len(r) <= 44 else r[:42] + "…")
        if excluded and status != "found":
            text += "\nexcluded"
        it = QTableWidgetItem(text)
        tip = [f"{key[0]} / {key[1]}"]
        path = pose.images.get(key[1])
        if path is not None:
            tip.append(str(path))
        if det is not None and getattr(det, "reason", None):
            tip.append(f"{status}: {det.reason}")
        elif det is not None and getattr(det, "variant_text", ""):
            tip.append(f"found on: {det.variant_text}")
        if excluded:
            tip.append("excluded from calibration (page 3)")
        it.setToolTip("\n".join(tip))
        it.setBackground(QColor("#eeeeee" if excluded else STATUS_COLOURS.get(status, "#ffffff")))
        it.setForeground(QColor("black"))
        thumb = self.model.thumbnails.get(key)
        if thumb is not None:
            it.setIcon(QIcon(qpixmap(thumb)))
        it.setData(Qt.ItemDataRole.UserRole, key)
        self.table.setItem(row, col, it)

    def _summary(self) -> None:
        s = self.model.session
        if s is None:
            self.summary.setText("No session open (page 1).")
            return
        counts = {"found": 0, "failed": 0, "missing": 0}
        for k in self.model.keys():
            d = self.model.detections.get(k)
            st = getattr(d, "status", None)
            if st is None and k[1] not in s.pose(k[0]).images:
                st = "missing"
            if st in counts:
                counts[st] += 1
        pending = len(self.model.keys()) - sum(counts.values())
        per_cam = []
        for c in s.camera_names:
            n = sum(1 for p in s.poses if getattr(self.model.detections.get((p.name, c)), "status", None) == "found")
            n_img = sum(1 for p in s.poses if c in p.images)
            done = all((p.name, c) in self.model.detections for p in s.poses if c in p.images)
            # the rate only when the camera's detection is complete (a running count is no rate)
            per_cam.append(f"{c}: {n} of {n_img}" + (f" ({100.0 * n / n_img:.0f} %)" if n_img and done else ""))
        txt = (f"<b>{len(s.poses)} poses × {len(s.camera_names)} cameras</b> — {counts['found']} found, "
               f"{counts['failed']} failed, {counts['missing']} missing"
               + (f", {pending} not detected yet" if pending else "")
               + f". Boards found per camera: {', '.join(per_cam)}. Board: {s.board.describe()}.")
        self.summary.setText(txt)
        low = [c for c in s.camera_names
               if sum(1 for p in s.poses if getattr(self.model.detections.get((p.name, c)), "status", None) == "found") < 3]
        hint = self.model.board_hint
        self.use_hint_btn.setVisible(hint is not None)
        if hint is not None:
            self.use_hint_btn.setText(f"Use a {hint[0]} x {hint[1]} board")
        if not pending and hint is not None:
            set_banner(self.message, f"⚠ {self.model.board_hint_text()} Use the button to set it and detect "
                                     "again, or set the board on page 1.", error=True)
        elif not pending and low and s.poses:
            set_banner(self.message, f"⚠ fewer than 3 boards found for {', '.join(low)}: "
                                     "those cameras cannot be calibrated. Add poses or fix the detections (page 3).")
        elif not s.poses:
            set_banner(self.message, "The session has no poses yet: add pose folders (button or drag and drop).")
        else:
            set_banner(self.message, "")

    # ------------------------------------------------------------------ actions
    def _open_review(self, row: int, col: int) -> None:
        it = self.table.item(row, col)
        key = it.data(Qt.ItemDataRole.UserRole) if it else None
        if key:
            self.actions.show_view(key[1], key[0])

    def _use_hint(self) -> None:
        if self.actions.is_busy():
            set_banner(self.message, "⚠ wait until the running job finishes (or cancel it)", error=True)
            return
        if not self.model.use_board_hint():
            set_banner(self.message, "⚠ cannot save the session's board size: set it on page 1", error=True)
            return
        self.actions.set_session(self.model.session)  # forgets the detections and detects again

    def _add(self) -> None:
        d = QFileDialog.getExistingDirectory(self, "Add a pose (folder with one image per camera)")
        if d:
            self.add_folders([Path(d)])

    def add_folders(self, dirs: list[Path]) -> list[str]:
        s = self.model.session
        if s is None:
            set_banner(self.message, "⚠ open or create a session first (page 1)", error=True)
            return []
        if self.actions.is_busy():
            set_banner(self.message, "⚠ wait until the running job finishes (or cancel it)", error=True)
            return []
        added, problems = self.model.add_pose_folders(dirs)
        if problems:
            set_banner(self.message, "⚠ " + "; ".join(problems), error=True)
        if added:
            keys = {(p, c) for p in added for c in s.pose(p).images}
            self.actions.run_detection(keys)
        return added

    def selected_poses(self) -> list[str]:
        s = self.model.session
        rows = sorted({i.row() for i in self.table.selectedIndexes()})
        return [s.poses[r].name for r in rows if s is not None and r < len(s.poses)]

    def _remove(self) -> None:
        poses = self.selected_poses()
        if not poses:
            set_banner(self.message, "Select the poses (rows) to remove first.")
            return
        r = QMessageBox.question(self, "Remove poses",
                                 f"Delete {len(poses)} pose folder(s) from the session?\n" + ", ".join(poses))
        if r == QMessageBox.StandardButton.Yes:
            self.remove_poses(poses)

    def remove_poses(self, poses: list[str]) -> None:
        problems = self.model.remove_poses(poses)
        if problems:
            set_banner(self.message, "⚠ " + "; ".join(problems), error=True)
