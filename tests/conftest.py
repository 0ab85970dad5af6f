"""Shared fixtures. The demo (synthetic rig, recording, ground truth, calibration session) is
written once per test session and shared read-only by CLI and GUI tests."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

os.environ.setdefault("QT_API", "pyside6")
os.environ.setdefault("PYVISTA_OFF_SCREEN", "false")
# the app's QSettings (Open recent, window state) of every test and of the programs the tests start
# go to a folder of the run's own, never to the user's ~/.config (the technician's Open recent
# listed /tmp/pytest-of-... entries); set before any QSettings is made
if not os.environ.get("PLANTREG_TESTS_KEEP_CONFIG"):
    import tempfile

    os.environ["XDG_CONFIG_HOME"] = tempfile.mkdtemp(prefix="plantreg-tests-config-")

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
        pytest.skip(f"shared data folder not found at {SHARED} (put shared/ beside the project or set "
                    "PLANTREG_SHARED_DATA)")
    return SHARED


# ---------------------------------------------------------------------- the registration workspace
@pytest.fixture(scope="session")
def demo_registered(demo_dir):
    """The demo read and registered into ``ir`` once per test session, as the workspace's jobs
    return it (Qt-free): ``{"loaded": load_job output, "registered": register_job output}``.
    Apply copies with :func:`workspace_session_outputs`; never mutate these."""
    from plantreg_gui.core.progress import Reporter
    from plantreg_gui.models.registration import load_job, register_job

    loaded = load_job(demo_dir / "rig.json", demo_dir / "recording", None, {}, progress=Reporter())
    registered = register_job(None, loaded["rig"], loaded["recording"], "ir", {}, progress=Reporter())
    return {"loaded": loaded, "registered": registered}


def workspace_session_outputs(demo_registered) -> tuple[dict, dict]:
    """Shallow copies of the cached job outputs whose mutable parts (renderings, cloud colours)
    a test may change without affecting the next test."""
    import copy

    loaded = dict(demo_registered["loaded"], renders=dict(demo_registered["loaded"]["renders"]))
    reg = dict(demo_registered["registered"])
    reg["renders"] = dict(reg["renders"])
    cloud = copy.copy(reg["cloud"])
    cloud.colours = dict(cloud.colours)
    reg["cloud"] = cloud
    return loaded, reg


@pytest.fixture(autouse=True)
def _gui_startup(request):
    """GUI tests start as ``plantreg-gui`` does: the 3D stack imported before any window exists
    (gui/startup.py). Once per process; non-GUI tests skip it."""
    if request.node.get_closest_marker("gui") is None:
        yield
        return
    from PySide6.QtWidgets import QApplication

    from plantreg_gui.gui.startup import preload

    preload()
    # Tests share one QApplication: one that quit it would make every later nested event loop
    # (qtbot.wait, QDialog.exec) return at once -- workers' results never arrive, tests hang.
    quits = []
    mp = pytest.MonkeyPatch()
    mp.setattr(QApplication, "exit", staticmethod(lambda code=0: quits.append(code)))
    mp.setattr(QApplication, "quit", staticmethod(lambda: quits.append(0)))
    try:
        yield
    finally:
        mp.undo()
    assert not quits, "the test quit the shared QApplication"


@pytest.fixture
def no_qt_leaks(qapp):
    """Fail a test that leaves top-level widgets open or worker threads running (as napari's and
    pyvistaqt's conftests do). Yields; checks after the test."""
    from PySide6.QtCore import QThread
    from PySide6.QtWidgets import QApplication

    before = {id(w) for w in QApplication.topLevelWidgets()}
    yield
    for _ in range(3):  # let deleteLater() happen
        QApplication.sendPostedEvents(None, 0)
        QApplication.processEvents()
    left = [w for w in QApplication.topLevelWidgets() if id(w) not in before and w.isVisible()]
    from plantreg_gui.gui.workers import Worker

    threads = [t for t in qapp.findChildren(QThread) if t.isRunning()]
    workers = [w for w in list(Worker.running) if w.is_running()]
    assert not left, f"test left widgets open: {[type(w).__name__ for w in left]}"
    assert not threads and not workers, f"test left {len(threads) + len(workers)} worker thread(s) running"


@pytest.fixture
def workspace(qapp, qtbot, no_qt_leaks, tmp_path):
    """A fresh, shown registration workspace with its own QSettings; shut down after the test."""
    from PySide6.QtCore import QSettings

    from plantreg_gui.gui.registration.workspace import RegistrationWorkspace

    for fmt in (QSettings.Format.NativeFormat, QSettings.Format.IniFormat):
        QSettings.setPath(fmt, QSettings.Scope.UserScope, str(tmp_path / "qsettings"))
    w = RegistrationWorkspace()
    w.resize(1300, 850)
    w.show()
    yield w
    w.shutdown()
    w.close()
    w.deleteLater()


@pytest.fixture
def registered_workspace(workspace, demo_registered):
    """:func:`workspace` showing the cached demo registration (no worker runs)."""
    loaded, reg = workspace_session_outputs(demo_registered)
    workspace.session.apply_loaded(loaded)
    workspace._registered(reg)
    return workspace
