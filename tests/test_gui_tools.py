"""GUI tools of issue 11: the export dialog from the core's registry, the region tool, saving the
view as PNG, absolute and locked display limits, band pickers in nm.

Each test gets a fresh workspace (conftest ``workspace`` / ``registered_workspace``) and fails if
it leaves widgets or worker threads behind; expected values come from the registration result or
synthetic data with known values, never from the GUI's own earlier output.
"""

from __future__ import annotations

import numpy as np
import pytest

from plantreg_gui.core import export

from test_export_registry import _extra_part

pytestmark = pytest.mark.gui


# ---------------------------------------------------------------------- export parts: one registry
def test_export_dialog_offers_the_registry(qapp, no_qt_leaks, monkeypatch):
    from plantreg_gui.gui.registration.export_dialog import ExportDialog

    monkeypatch.setattr(export, "OUTPUT_PARTS", (*export.OUTPUT_PARTS, _extra_part()))
    dlg = ExportDialog("/tmp/x")
    try:
        assert dlg.boxes["extra"].text() == "An extra part (text)"
        assert dlg.what() == list(export.OUTPUTS) + ["extra"]
    finally:
        dlg.deleteLater()
