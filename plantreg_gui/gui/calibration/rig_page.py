"""Page 1: rig and board — open or create a capture session, cameras, depth camera, board.

Length: the rig and board form, its live board preview and the session-contents summary are one
page a technician fills in together; the parsing helpers (bands) sit at the top.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from PySide6.QtCore import QPointF, Qt, QTimer
from PySide6.QtGui import QColor, QPainter, QPen
from PySide6.QtWidgets import (QAbstractItemView, QComboBox, QDoubleSpinBox, QFileDialog, QFormLayout,
                               QGroupBox, QHBoxLayout, QHeaderView, QLabel, QLineEdit, QPushButton,
                               QSizePolicy, QSpinBox, QTableWidget, QTableWidgetItem, QVBoxLayout, QWidget)

from ...core.camera import modality
from .page import WizardPage
from .widgets import banner, qpixmap, set_banner

#: the modality chooser offers the registry's canonical names (an alias typed in is canonicalised on save)
MODALITIES = modality.names()
DICTIONARIES = ["DICT_4X4_50", "DICT_4X4_100", "DICT_4X4_250", "DICT_5X5_100", "DICT_5X5_250",
                "DICT_6X6_250", "DICT_7X7_250", "DICT_ARUCO_ORIGINAL"]



def parse_bands(text: str) -> list[float]:
    """Band centres (nm) from 'FIRST-LAST/COUNT' (evenly spaced) or a list '450, 550, 650'."""
    t = text.replace("nm", "").strip()
    try:
        if "/" in t:
            span, n = t.split("/", 1)
            a, b = (float(x) for x in span.replace("–", "-").split("-", 1))
            n = int(n)
            if n < 1 or not b > a:
                raise ValueError
            return [float(v) for v in np.linspace(a, b, n)] if n > 1 else [a]
        vals = [float(x) for x in t.replace(";", ",").split(",") if x.strip()]
    except ValueError:
        raise ValueError(f"'{text}' must be a list '450, 550, 650' or 'FIRST-LAST/COUNT' (nm)") from None
    if not vals or any(v <= 0 for v in vals):
        raise ValueError(f"'{text}' must be positive wavelengths in nm")
    return vals


def format_bands(bands) -> str:
    """The inverse of :func:`parse_bands` (evenly spaced lists as 'FIRST-LAST/COUNT')."""
    if not bands:
        return ""
    b = np.asarray(bands, float)
    if len(b) > 3 and np.allclose(np.diff(b), (b[-1] - b[0]) / (len(b) - 1), rtol=0, atol=0.011):
        return f"{b[0]:g}-{b[-1]:g}/{len(b)}"
    return ", ".join(f"{v:g}" for v in b)

class RigPage(WizardPage):
    title = "Rig and board"

    def __init__(self, model, actions) -> None:
        super().__init__(model, actions)
        self._loading = False
        outer = QVBoxLayout(self)

        # --- session
        box = QGroupBox("Capture session")
        h = QHBoxLayout(box)
        self.folder = QLineEdit()
        self.folder.setReadOnly(True)
        self.folder.setPlaceholderText("no session open — open a folder with session.json, or create a new one")
        self.open_btn = QPushButton("Open session…")
        self.new_btn = QPushButton("Create new session…")
        self.open_btn.clicked.connect(self._open)
        self.new_btn.clicked.connect(self._create)
        # the form's messages and its Save button at the top, beside the session they change: at
        # the foot of the page they were below the fold of a 1280 x 720 window
        self.apply_btn = QPushButton("Save changes to session")
        self.apply_btn.setToolTip("Write cameras, depth and board to session.json (detections are redone)")
        self.apply_btn.clicked.connect(self._apply)
        h.addWidget(QLabel("Folder:"))
        h.addWidget(self.folder, 1)
        h.addWidget(self.open_btn)
        h.addWidget(self.new_btn)
        h.addWidget(self.apply_btn)
        outer.addWidget(box)
        self.message = banner()
        outer.addWidget(self.message)

        row = QHBoxLayout()
        outer.addLayout(row, 1)

        # --- cameras
        cbox = QGroupBox("Cameras")
        cl = QVBoxLayout(cbox)
        self.cameras = QTableWidget(0, 5)
        self.cameras.setHorizontalHeaderLabels(["Name (= file name)", "Modality", "Units", "Bands (nm)",
                                                "Lens file"])
        self.cameras.horizontalHeaderItem(4).setToolTip(
            "Optional: a rig file (e.g. this camera calibrated on its own, or the maker's values) whose K and "
            "distortion this camera keeps; only its pose is calibrated. With standard errors in the file (a "
            "plantreg calibration) they are priors. Double-click to type the path (relative to the session "
            "folder or absolute); empty = calibrate the lens here")
        self.cameras.horizontalHeaderItem(2).setToolTip("What a pixel value means, e.g. degC, DN, reflectance "
                                                        "(kept in the rig file)")
        self.cameras.horizontalHeaderItem(3).setToolTip("Band centres of a multi-band camera in nm: a list "
                                                        "'450, 550, 650' or evenly spaced 'FIRST-LAST/COUNT', e.g. "
                                                        "'400-1000/100' (kept in the rig file; the registration "
                                                        "shows spectra in nm with it)")
        # every column as wide as its header and cells ("lame (= file name" and "ıyperspectral" were cut
        # when name and modality shared what was left); the lens file takes the rest; the table scrolls
        self.cameras.horizontalHeader().setSectionResizeMode(QHeaderView.ResizeMode.ResizeToContents)
        self.cameras.horizontalHeader().setStretchLastSection(True)
        self.cameras.horizontalHeader().setSectionResizeMode(1, QHeaderView.ResizeMode.Interactive)
        self.cameras.setSelectionBehavior(QAbstractItemView.SelectionBehavior.SelectRows)
        self.cameras.itemChanged.connect(self._changed)
        self.cameras.setMaximumHeight(230)
        cl.addWidget(self.cameras, 1)
        hb = QHBoxLayout()
        add = QPushButton("Add camera")
        rem = QPushButton("Remove camera")
        add.clicked.connect(lambda: self._add_camera(f"camera{self.cameras.rowCount() + 1}", "rgb"))
        rem.clicked.connect(self._remove_camera)
        hb.addWidget(add)
        hb.addWidget(rem)
        hb.addStretch(1)
        cl.addLayout(hb)
        f = QFormLayout()
        self.depth_cam = QComboBox()
        self.depth_cam.setToolTip("The camera whose pixels the depth map is aligned with (the ToF camera's "
                                  "infrared image). 'none' for a rig without a depth camera.")
        self.depth_cam.currentIndexChanged.connect(self._changed)
        self.depth_scale = QDoubleSpinBox()
        self.depth_scale.setDecimals(6)
        self.depth_scale.setRange(1e-6, 10.0)
        self.depth_scale.setSingleStep(0.0001)
        self.depth_scale.setValue(0.001)
        self.depth_scale.setSuffix(" m per unit")
        self.depth_scale.setToolTip("Metres per depth-map unit (Azure Kinect: 0.001, millimetres)")
        self.depth_scale.valueChanged.connect(self._changed)
        f.addRow("Depth map aligned with:", self.depth_cam)
        f.addRow("Depth scale:", self.depth_scale)
        cl.addLayout(f)
        self.contents = QLabel()
        self.contents.setWordWrap(True)
        self.contents.setTextFormat(Qt.TextFormat.RichText)
        self.contents.setAlignment(Qt.AlignmentFlag.AlignTop)
        self.contents.setStyleSheet("QLabel { background: white; border: 1px solid #cccccc; padding: 6px; }")
        cl.addWidget(self.contents, 1)
        row.addWidget(cbox, 1)

        # --- board
        bbox = QGroupBox("Calibration board")
        bl = QHBoxLayout(bbox)
        bf = QFormLayout()
        self.btype = QComboBox()
        self.btype.addItems(["chessboard", "charuco"])
        self.columns = QSpinBox()
        self.columns.setRange(1, 200)
        self.rows = QSpinBox()
        self.rows.setRange(1, 200)
        self.square = QDoubleSpinBox()
        self.square.setRange(0.0, 1000.0)
        self.square.setDecimals(2)
        self.square.setSuffix(" mm")
        self.marker = QDoubleSpinBox()
        self.marker.setRange(0.0, 1000.0)
        self.marker.setDecimals(2)
        self.marker.setSuffix(" mm")
        self.dictionary = QComboBox()
        self.dictionary.addItems(DICTIONARIES)
        for w in (self.btype, self.dictionary):
            w.currentIndexChanged.connect(self._changed)
        for w in (self.columns, self.rows, self.square, self.marker):
            w.valueChanged.connect(self._changed)
        bf.addRow("Type:", self.btype)
        bf.addRow("Inner corners across:", self.columns)
        bf.addRow("Inner corners down:", self.rows)
        bf.addRow("Square size:", self.square)
        bf.addRow("Marker size:", self.marker)
        bf.addRow("ArUco dictionary:", self.dictionary)
        hint = QLabel("<b>Count the INNER corners</b> — the points where four squares meet, not the squares. "
                      "A board of 10 × 7 squares has 9 × 6 inner corners. Prefer an odd + even count "
                      "(e.g. 9 × 6): such a board has a unique orientation.")
        hint.setWordWrap(True)
        bf.addRow(hint)
        left = QWidget()
        left.setLayout(bf)
        bl.addWidget(left, 1)
        pv = QVBoxLayout()
        self.preview = QLabel()
        self.preview.setAlignment(Qt.AlignmentFlag.AlignCenter)
        self.preview.setMinimumSize(300, 220)
        self.preview.setSizePolicy(QSizePolicy.Policy.Expanding, QSizePolicy.Policy.Expanding)
        self.preview.setStyleSheet("background: #f4f4f4; border: 1px solid #cccccc;")
        self.preview_caption = QLabel()
        self.preview_caption.setAlignment(Qt.AlignmentFlag.AlignCenter)
        self.preview_caption.setWordWrap(True)
        pv.addWidget(self.preview, 1)
        pv.addWidget(self.preview_caption)
        bl.addLayout(pv, 1)
        row.addWidget(bbox, 2)


        self._preview_timer = QTimer(self)
        self._preview_timer.setSingleShot(True)
        self._preview_timer.setInterval(120)  # throttle: one redraw after the spin boxes settle
        self._preview_timer.timeout.connect(self._update_preview)
        self._set_defaults()
        self.model.session_changed.connect(self.refresh)
        self.model.poses_changed.connect(self._contents)

    # ------------------------------------------------------------------ form <-> session
    def _set_defaults(self) -> None:
        self._loading = True
        for name, mod in (("ir", "infrared"), ("rgb", "rgb"), ("thermal", "thermal")):
            self._add_camera(name, mod)
        self.columns.setValue(9)
        self.rows.setValue(6)
        self.square.setValue(25.0)
        self.marker.setValue(18.0)
        self._loading = False
        self._refresh_depth_combo("ir")
        self._changed()

    def _add_camera(self, name: str, modality: str, units: str = "", bands: str = "", intrinsics: str = "") -> None:
        r = self.cameras.rowCount()
        self.cameras.insertRow(r)
        self.cameras.setItem(r, 0, QTableWidgetItem(name))
        self.cameras.setItem(r, 2, QTableWidgetItem(units))
        self.cameras.setItem(r, 3, QTableWidgetItem(bands))
        self.cameras.setItem(r, 4, QTableWidgetItem(intrinsics))
        combo = QComboBox()
        combo.setEditable(True)
        combo.addItems(MODALITIES)
        combo.setCurrentText(modality)
        combo.currentTextChanged.connect(self._changed)
        self.cameras.setCellWidget(r, 1, combo)
        # a cell widget is not measured by ResizeToContents: the column takes the widest combo
        self.cameras.setColumnWidth(1, max(self.cameras.columnWidth(1), combo.sizeHint().width()))
        self._refresh_depth_combo()
        self._changed()

    def _remove_camera(self) -> None:
        rows = sorted({i.row() for i in self.cameras.selectedIndexes()}, reverse=True)
        if not rows and self.cameras.rowCount():
            rows = [self.cameras.rowCount() - 1]
        for r in rows:
            self.cameras.removeRow(r)
        self._refresh_depth_combo()
        self._changed()

    def _camera_names(self) -> list[str]:
        out = []
        for r in range(self.cameras.rowCount()):
            it = self.cameras.item(r, 0)
            out.append(it.text().strip() if it else "")
        return out

    def _refresh_depth_combo(self, select: str | None = None) -> None:
        cur = select if select is not None else self.depth_cam.currentText()
        self.depth_cam.blockSignals(True)
        self.depth_cam.clear()
        self.depth_cam.addItem("none")
        names = [n for n in self._camera_names() if n]
        self.depth_cam.addItems(names)
        self.depth_cam.setCurrentText(cur if cur in names else "none")
        self.depth_cam.blockSignals(False)

    def refresh(self) -> None:
        """Show the open session's rig and board."""
        s = self.model.session
        if s is None:
            return
        self._loading = True
        self.folder.setText(str(s.folder))
        self.cameras.setRowCount(0)
        for n, m in s.cameras.items():
            meta = s.camera_meta.get(n, {})
            self._add_camera(n, m, meta.get("units", ""), format_bands(meta.get("bands")), meta.get("intrinsics", ""))
        b = s.board
        self.btype.setCurrentText(b.type)
        self.columns.setValue(b.columns)
        self.rows.setValue(b.rows)
        self.square.setValue(b.square_size * 1000)
        if b.marker_size:
            self.marker.setValue(b.marker_size * 1000)
        if b.dictionary:
            self.dictionary.setCurrentText(b.dictionary)
        self.depth_scale.setValue(s.depth_scale)
        self._refresh_depth_combo(s.depth_camera or "none")
        self._loading = False
        self._changed()
        self._contents()

    def _contents(self) -> None:
        """What the session folder holds: poses, images per camera, depth maps."""
        s = self.model.session
        if s is None:
            self.contents.setText("")
            return
        rows = "".join(
            f"<tr><td>{c}</td><td align=right>{sum(1 for p in s.poses if c in p.images)}</td>"
            f"<td>&nbsp;{'(+ depth maps: ' + str(sum(1 for p in s.poses if p.depth)) + ')' if c == s.depth_camera else ''}</td></tr>"
            for c in s.camera_names)
        self.contents.setText(
            f"<b>Session contents</b>: {len(s.poses)} pose folders"
            f"<table cellspacing=3><tr><th align=left>camera</th><th>images</th><th></th></tr>{rows}</table>"
            "<p style='color:#555555'>Each pose folder holds one image per camera, named after the camera "
            "(e.g. <i>ir.png</i>, <i>thermal.tif</i>), and the depth map <i>depth.png</i>. "
            "Cover the depth range of the plants and all of each image; heat the board for thermal "
            "cameras.</p>")

    def form(self) -> tuple[object | None, dict[str, str], str | None, float, list[str]]:
        """(board or None, cameras, depth camera, depth scale, problems) from the form."""
        from ...core.calibration import Board

        problems: list[str] = []
        cams: dict[str, str] = {}
        for r, n in enumerate(self._camera_names()):
            combo = self.cameras.cellWidget(r, 1)
            mod = combo.currentText().strip() if combo else "unknown"
            if not n:
                problems.append(f"camera {r + 1} has no name")
            elif ":" in n or "/" in n or n == "depth":
                problems.append(f"camera name '{n}' is not allowed (no ':' or '/', and not 'depth')")
            elif n in cams:
                problems.append(f"camera name '{n}' is used twice")
            else:
                cams[n] = mod or "unknown"
        if not cams and not problems:
            problems.append("add at least one camera")
        problems += self.camera_meta()[1]
        depth = self.depth_cam.currentText()
        depth = None if depth in ("", "none") else depth
        if depth is not None and depth not in cams:
            problems.append(f"the depth camera '{depth}' is not among the cameras")
        board = None
        kw = dict(type=self.btype.currentText(), columns=self.columns.value(), rows=self.rows.value(),
                  square_size=self.square.value() / 1000.0)
        if kw["type"] == "charuco":
            kw.update(marker_size=self.marker.value() / 1000.0, dictionary=self.dictionary.currentText())
        try:
            board = Board(**kw)
        except ValueError as e:
            problems.append(str(e))
        return board, cams, depth, self.depth_scale.value(), problems

    def camera_meta(self) -> tuple[dict[str, dict], list[str]]:
        """Units, bands and known intrinsics per camera from the table ({name: {"units", "bands",
        "intrinsics"}}), and problems."""
        meta: dict[str, dict] = {}
        problems: list[str] = []
        for r, n in enumerate(self._camera_names()):
            m: dict = {}
            units = self.cameras.item(r, 2).text().strip() if self.cameras.item(r, 2) else ""
            text = self.cameras.item(r, 3).text().strip() if self.cameras.item(r, 3) else ""
            if units:
                m["units"] = units
            intr = self.cameras.item(r, 4).text().strip() if self.cameras.item(r, 4) else ""
            if intr:
                base = Path(self.model.session.folder) if self.model.session is not None else Path.cwd()
                if not (Path(intr) if Path(intr).is_absolute() else base / intr).is_file():
                    problems.append(f"camera '{n}': known intrinsics file not found: {intr}")
                m["intrinsics"] = intr
            known = (self.model.session.camera_meta.get(n, {}).get("bands")
                     if self.model.session is not None else None)
            if text and known and text == format_bands(known):
                m["bands"] = list(known)  # unchanged: keep the file's values (the text rounds them)
            elif text:
                try:
                    m["bands"] = parse_bands(text)
                except ValueError as e:
                    problems.append(f"camera '{n}': bands {e}")
            if m and n:
                meta[n] = m
        return meta, problems

    def _changed(self, *_) -> None:
        if self._loading:
            return
        charuco = self.btype.currentText() == "charuco"
        self.marker.setEnabled(charuco)
        self.dictionary.setEnabled(charuco)
        self.depth_scale.setEnabled(self.depth_cam.currentText() not in ("", "none"))
        names = [n for n in self._camera_names() if n]
        if sorted(names) != sorted(self.depth_cam.itemText(i) for i in range(1, self.depth_cam.count())):
            self._refresh_depth_combo()
        board, cams, depth, scale, problems = self.form()
        if problems:
            set_banner(self.message, "⚠ " + "; ".join(problems), error=True)
        else:
            s = self.model.session
            warn = []
            if board is not None and board.is_symmetric:
                warn.append(f"{board.columns} × {board.rows} is symmetric (both counts even or both odd): "
                            "the corner order of a rotated board is ambiguous. Prefer e.g. 9 × 6.")
            if s is not None and self._differs(board, cams, depth, scale):
                warn.append("The form differs from the session — 'Save changes to session' to use it.")
            set_banner(self.message, " ".join(warn))
        self.apply_btn.setEnabled(not problems and self.model.session is not None
                                  and self._differs(board, cams, depth, scale))
        self.new_btn.setEnabled(not problems)
        self._preview_timer.start()

    def _differs(self, board, cams, depth, scale) -> bool:
        s = self.model.session
        if s is None or board is None:
            return False
        cams = {n: modality.canonical(m) for n, m in cams.items()}  # the session holds canonical names
        return (board.to_dict() != s.board.to_dict() or cams != s.cameras or depth != s.depth_camera
                or (depth is not None and abs(scale - s.depth_scale) > 1e-12)
                or self.camera_meta()[0] != {n: m for n, m in s.camera_meta.items() if m})

    def _update_preview(self) -> None:
        board, *_rest, problems = self.form()
        if board is None:
            self.preview.clear()
            self.preview.setText("(no preview: fix the board geometry)")
            self.preview_caption.setText("")
            return
        pps = int(max(6, min(40, 480 / max(board.columns + 2, board.rows + 2))))
        img = board.render(px_per_square=pps, margin_squares=0.5)
        rgb = np.repeat(img[:, :, None], 3, axis=2).copy()
        pm = qpixmap(rgb)
        # mark the inner corners: what the counts refer to
        p = QPainter(pm)
        p.setRenderHint(QPainter.RenderHint.Antialiasing)
        o = (1 + 0.5) * pps - 0.5
        r = max(2.5, pps * 0.2)
        for j in range(board.rows):
            for i in range(board.columns):
                p.setPen(QPen(QColor("white"), 1))
                p.setBrush(QColor("#e8702a"))
                p.drawEllipse(QPointF(o + i * pps, o + j * pps), r, r)
        p.setBrush(QColor("#ff2020"))
        p.setPen(QPen(QColor("#ff2020"), max(2.0, pps * 0.08)))
        p.drawEllipse(QPointF(o, o), r, r)
        p.setBrush(Qt.BrushStyle.NoBrush)
        p.drawEllipse(QPointF(o, o), 2.6 * r, 2.6 * r)
        p.end()
        self.preview.setPixmap(pm.scaled(self.preview.size() * 0.98, Qt.AspectRatioMode.KeepAspectRatio,
                                         Qt.TransformationMode.SmoothTransformation))
        w, h = board.size_m
        self.preview_caption.setText(
            f"{board.columns + 1} × {board.rows + 1} squares → {board.columns} × {board.rows} inner corners "
            f"(dots; red = corner 0). Printed pattern {w * 1000:.0f} × {h * 1000:.0f} mm.")

    def resizeEvent(self, event) -> None:  # noqa: N802
        super().resizeEvent(event)
        self._preview_timer.start()

    def showEvent(self, event) -> None:  # noqa: N802
        super().showEvent(event)
        self._contents()  # poses may have been added or removed on page 2

    # ------------------------------------------------------------------ actions
    def _open(self) -> None:
        d = QFileDialog.getExistingDirectory(self, "Open capture session (folder with session.json)")
        if d:
            self.actions.open_session(Path(d))

    def _create(self) -> None:
        d = QFileDialog.getExistingDirectory(self, "Folder for the new capture session")
        if d:
            self.create_session(Path(d))

    def create_session(self, folder: Path) -> bool:
        from ...core.calibration import Session
        from ...core.errors import PlantregError

        board, cams, depth, scale, problems = self.form()
        if problems or board is None:
            set_banner(self.message, "⚠ " + "; ".join(problems), error=True)
            return False
        try:
            s = Session.create(folder, board, cams, depth, scale)
            s.camera_meta = self.camera_meta()[0]
            s.save()
        except (PlantregError, OSError) as e:
            set_banner(self.message, f"⚠ {e}", error=True)
            return False
        self.actions.set_session(s)
        return True

    def _apply(self) -> None:
        self.apply_changes()

    def leave(self) -> bool:
        """Going on needs a session; edits not yet applied are applied first."""
        if self.model.session is None:
            set_banner(self.message, "⚠ Open a capture session (or create one) before going on.", error=True)
            return False
        if self.apply_btn.isEnabled():
            self.apply_changes()
        return True

    def apply_changes(self) -> bool:
        from ...core.errors import PlantregError

        s = self.model.session
        board, cams, depth, scale, problems = self.form()
        if s is None or problems or board is None:
            return False
        s.board, s.cameras, s.depth_camera, s.depth_scale = board, cams, depth, scale
        s.camera_meta = self.camera_meta()[0]
        try:
            s.save()
            s.rescan()
        except (PlantregError, OSError) as e:
            set_banner(self.message, f"⚠ cannot save the session: {e}", error=True)
            return False
        self.actions.set_session(s)
        return True
