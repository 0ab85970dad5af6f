"""Shared fixtures. The demo (synthetic rig, recording, ground truth, calibration session) is
written once per test session and shared read-only by CLI and GUI tests."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

os.environ.setdefault("QT_API", "pyside6")
os.environ.setdefault("PYVISTA_OFF_SCREEN", "false")

# `shared/` lies beside the project root (as in CI); PLANTREG_SHARED_DATA overrides it
SHARED = Path(os.environ.get("PLANTREG_SHARED_DATA", Path(__file__).resolve().parents[2] / "shared" / "data"))


@pytest.fixture(scope="session")
def demo_dir(tmp_path_factory) -> Path:
    """A demo folder as `plantreg demo --clean` writes it (rig.json, recording/, ground_truth/,
    calibration/): the ideal recording, so accuracy figures keep their meaning. Tests must not modify it."""
    from plantreg_gui.core.synthetic import write_demo

    folder = tmp_path_factory.mktemp("demo") / "demo"
    write_demo(folder, clean=True)
    return folder


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """`../shared/data` beside the project (real data sets)."""
    if not SHARED.is_dir():
        pytest.fail(f"shared data folder not found at {SHARED} (put shared/ beside the project or set PLANTREG_SHARED_DATA)")
    return SHARED
