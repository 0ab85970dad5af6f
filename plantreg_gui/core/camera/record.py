"""The rig's calibration record (``"calibration"`` in a rig file): how the rig was made, from what,
and how well it fits -- one typed record, written by everything that makes a rig (``plantreg
fit-rig`` with or without ``--refine``/``--silhouette``, the landmark page's fit and nudge,
``plantreg rig create``) and read by everything that needs it (the mixed-pixel flag's
registration uncertainty, reports).

On file it is a flat JSON object: the typed fields below plus the maker's own report keys
(residual lists, leave-one-out, priors, ...), kept as they are. Records written before this
type existed (no ``record_version``) are read too: their residuals count as landmark residuals
when the method names landmarks or a nudge.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from datetime import datetime, timezone
from typing import Any

RECORD_VERSION = 1
#: keys of the typed part; everything else in the JSON object is ``details``
_TYPED = ("record_version", "method", "source", "date", "per_camera", "residual_kind", "uncertainty_px")


@dataclass
class CalibrationRecord:
    """``method``: what made the rig (``landmarks``, ``landmarks+refine``, ``landmarks+silhouette``,
    ``refine``, ``manual nudge``, ``start``, ...); ``source``: the tool (``plantreg fit-rig``,
    ``plantreg-gui landmark page``, ...); ``per_camera``: camera -> residual statistics
    (``n``, ``median_px``, ``p90_px``, ``max_px``); ``residual_kind``: what those residuals are
    (``"landmarks"``: clicked pairs; None: no per-camera residuals); ``uncertainty_px``: camera ->
    how far off, in its pixels, the mapping into it may be (the larger of the fitted and the
    leave-one-out median landmark residual); ``details``: the maker's report."""

    method: str
    source: str = ""
    date: str = field(default_factory=lambda: datetime.now(timezone.utc).isoformat(timespec="seconds"))
    per_camera: dict[str, dict[str, Any]] = field(default_factory=dict)
    residual_kind: str | None = None
    uncertainty_px: dict[str, float] = field(default_factory=dict)
    details: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        d = {"record_version": RECORD_VERSION, "method": self.method, "source": self.source, "date": self.date,
             "per_camera": self.per_camera, "residual_kind": self.residual_kind,
             "uncertainty_px": self.uncertainty_px}
        d.update({k: v for k, v in self.details.items() if k not in _TYPED})
        return d

    @classmethod
    def from_dict(cls, d: Any) -> "CalibrationRecord | None":
        """The record of a rig file's ``"calibration"`` entry (None if there is none usable)."""
        if not isinstance(d, dict) or not isinstance(d.get("method"), str):
            return None
        per = d.get("per_camera") if isinstance(d.get("per_camera"), dict) else {}
        kind = d.get("residual_kind")
        if "record_version" not in d:  # written before the record was typed
            m = d["method"].lower()
            kind = "landmarks" if per and ("landmark" in m or "nudge" in m) else None
        unc = d.get("uncertainty_px") if isinstance(d.get("uncertainty_px"), dict) else {}
        return cls(d["method"], str(d.get("source", "")), str(d.get("date", "")), per,
                   kind if isinstance(kind, str) else None, unc,
                   {k: v for k, v in d.items() if k not in _TYPED})

    @classmethod
    def of(cls, rig_extra: Any) -> "CalibrationRecord | None":
        """The record in a rig's ``extra`` (``rig.extra``), or None."""
        return cls.from_dict(rig_extra.get("calibration")) if isinstance(rig_extra, dict) else None

    def store(self, rig: Any) -> None:
        """Write the record into ``rig.extra["calibration"]`` (saved with the rig)."""
        rig.extra["calibration"] = self.to_dict()

    def registration_px(self, camera: str) -> float:
        """How far off, in ``camera``'s pixels, the mapping into it may be: its ``uncertainty_px``,
        else its median landmark residual; 0 for a camera without landmark residuals."""
        v = self.uncertainty_px.get(camera)
        if v is None and self.residual_kind == "landmarks":
            v = (self.per_camera.get(camera) or {}).get("median_px")
        try:
            v = float(v or 0.0)
        except (TypeError, ValueError):
            return 0.0
        return v if math.isfinite(v) and v > 0 else 0.0


def landmark_record(method: str, source: str, report: dict[str, Any], **details: Any) -> CalibrationRecord:
    """The record of a rig fitted to landmarks, from a fit report (``rigfit.fit_rig``'s, optionally
    with ``refine``/``silhouette`` entries) and further ``details`` (command, files, warnings)."""
    per = dict(report.get("per_camera", {}))
    loo = dict(report.get("leave_one_out", {}).get("per_camera", {}))
    loo.update({c: s for c, s in report.get("leave_one_landmark_out", {}).items() if c not in loo})
    unc = {}
    for c, s in per.items():
        vals = [s.get("median_px"), (loo.get(c) or {}).get("median_px")]
        vals = [float(v) for v in vals if isinstance(v, (int, float)) and math.isfinite(v)]
        if vals:
            unc[c] = max(vals)
    rest = {k: v for k, v in report.items() if k not in ("time_s", "method", "per_camera")}
    rest.update(details)
    return CalibrationRecord(method, source, per_camera=per, residual_kind="landmarks" if per else None,
                             uncertainty_px=unc, details=rest)
