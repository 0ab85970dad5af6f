"""The registration parameters a user may tune (edge angle, tolerances), bound to the session.

A change takes effect at the next Register; the edge angle shapes the meshes, so the session
drops its registrar and the meshes are rebuilt then.
"""

from __future__ import annotations

from dataclasses import replace

from PySide6.QtWidgets import QDoubleSpinBox, QFormLayout, QGroupBox, QLabel, QWidget


class ParamsPanel(QGroupBox):
    def __init__(self, session, parent: QWidget | None = None):
        super().__init__("Registration", parent)
        self.session = session
        p = session.params
        self.edge = self._box("edge_angle_deg", p.edge_angle_deg, " °",
                              "mesh edge cut: a depth-map edge seen more obliquely than this is cut (docs/registration.md)")
        self.occlusion = self._box("occlusion_tol_m", p.occlusion_tol_m, " mm",
                                   "a source-ray hit this much before the point counts as an occlusion (P2)")
        self.uncertainty = self._box("uncertainty_tol_m", p.uncertainty_tol_m, " mm",
                                     "an uncertainty-mesh hit this much before the point counts (P3.1, P3.2)")
        form = QFormLayout(self)
        form.addRow("Edge angle", self.edge)
        form.addRow("Occlusion tolerance", self.occlusion)
        form.addRow("Uncertainty tolerance", self.uncertainty)
        self.note = QLabel("")
        self.note.setStyleSheet("color: #555; font-size: 11px;")
        form.addRow(self.note)
        for sb in (self.edge, self.occlusion, self.uncertainty):
            sb.valueChanged.connect(self._changed)

    @staticmethod
    def _box(key: str, v: float, suffix: str, tip: str) -> QDoubleSpinBox:
        """A spin box for parameter ``key``, its range from the parameters' one table (shown in
        the table's unit: ``value * scale``)."""
        from ...core.registration.params import LIMITS

        lim = LIMITS[key]
        sb = QDoubleSpinBox()
        sb.setRange(lim.lo * lim.scale, lim.hi * lim.scale)
        sb.setDecimals(1)
        sb.setValue(v * lim.scale)
        sb.setSuffix(suffix)
        sb.setToolTip(tip)
        sb.setKeyboardTracking(False)  # one change per edit, not per typed digit
        return sb

    def _changed(self) -> None:
        p = replace(self.session.params, edge_angle_deg=self.edge.value(),
                    occlusion_tol_m=self.occlusion.value() / 1000.0,
                    uncertainty_tol_m=self.uncertainty.value() / 1000.0)
        self.session.set_params(p)
        self.note.setText("Press Register to apply." if self.session.result is not None else "")
