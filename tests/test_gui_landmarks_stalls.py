"""The landmark page's long work off the GUI thread.

Opening files: the recordings are read (and their images made ready for showing) on a worker,
not on the GUI thread (it blocked the GUI thread ~0.32 s on the real plants); the page says it is
reading, a bad file is a "Cannot open" dialog, and closing the page or opening again while it
reads is safe. Refine: runs in a child process (its camera threads no longer compete with the
GUI thread for the GIL), and Cancel stops it at once.

The thread checks are exact (who called the reader); the stall probe's figure is printed, with
the bound of tests/test_gui_landmarks.py, widened by a control process measured alongside
(stall_probe.LoadControl) so that a busy machine does not fail it.
"""

import threading
import time

import pytest

from plantreg_gui.core.data.recording import Recording

pytestmark = pytest.mark.gui

ALLOWED_GAP_S = 0.5  # on an idle machine; widened by a control measured alongside (stall_probe.LoadControl)


@pytest.fixture
def page(qtbot, no_qt_leaks):
    from plantreg_gui.gui.landmarks.page import LandmarkPage

    p = LandmarkPage()  # closed here, not by qtbot (its close comes before this teardown)
    p.resize(1200, 800)
    p.show()
    qtbot.waitExposed(p)
    yield p
    p.shutdown()
    qtbot.waitUntil(lambda: not p.is_busy(), timeout=60_000)
    from PySide6.QtWidgets import QMessageBox

    for box in p.findChildren(QMessageBox):  # the error dialogs shown (non-modal)
        box.close()
    p.close()
    p.deleteLater()


def _spy(monkeypatch, owner, name, on_gui_thread: list, delay_s: float = 0.0) -> None:
    """Replace ``owner.name`` by a wrapper recording, per call, whether the GUI thread made it."""
    orig = getattr(owner, name)

    def spy(*a, **k):
        on_gui_thread.append(threading.current_thread() is threading.main_thread())
        if delay_s:
            time.sleep(delay_s)
        return orig(*a, **k)

    monkeypatch.setattr(owner, name, spy)


def test_open_reads_the_recordings_on_a_worker(qtbot, page, demo_dir, tmp_path, monkeypatch):
    import plantreg_gui.gui.landmarks.page as page_module
    from stall_probe import LoadControl, StallProbe

    reads, conversions = [], []
    _spy(monkeypatch, Recording, "load", reads)
    _spy(monkeypatch, page_module, "to_rgb8", conversions)  # the shown images' colouring
    with LoadControl() as control, StallProbe() as probe:
        page.open(demo_dir / "rig.json", tmp_path / "landmarks.json", [demo_dir / "recording"])
        # back at once, and saying that it reads (before: the session was read on return)
        assert page.session is None and not reads
        assert page.is_busy() and page.progress.isVisible() and page.cancel_button.isEnabled()
        assert "Reading" in page.hint.text()
        qtbot.waitUntil(lambda: page.session is not None and not page.is_busy(), timeout=120_000)
    print(f"open: longest GUI-thread gap {probe.max_gap * 1000:.0f} ms")
    assert reads and not any(reads), "a recording was read on the GUI thread"
    assert conversions and not any(conversions), "an image was prepared for showing on the GUI thread"
    s = page.session
    assert s.recording_key is not None and s.camera is not None
    assert page.left.array is not None and page.right.array is not None
    assert page.recording_combo.currentText() == s.recording_key and page.fit_button.isEnabled()
    assert probe.max_gap < control.allowed(ALLOWED_GAP_S), probe.stalls(0.2)
    # another camera: converted when first chosen, then kept (choosing it again converts nothing)
    other = [c for c in s.camera_names() if c != s.camera][0]
    n = len(conversions)
    page.camera_combo.setCurrentText(other)
    page.camera_combo.setCurrentText(s.camera_names()[0] if other != s.camera_names()[0] else s.camera_names()[1])
    page.camera_combo.setCurrentText(other)
    assert len(conversions) == n  # all of the current recording's cameras were prepared by the worker


def test_a_bad_file_is_a_dialog_not_an_exception(qtbot, page, demo_dir, tmp_path):
    from plantreg_gui.gui import workers

    n = len(workers.SHOWN_ERRORS)
    bad = tmp_path / "landmarks.json"
    bad.write_text("{ not json")
    page.open(demo_dir / "rig.json", bad)  # before: raised InputError on the GUI thread
    qtbot.waitUntil(lambda: not page.is_busy(), timeout=60_000)
    assert page.session is None
    title, message = workers.SHOWN_ERRORS[n]
    assert title == "Cannot open" and "landmarks.json" in message and "Traceback" not in message
    page.open(demo_dir / "rig.json", tmp_path / "new.json")  # a new landmarks file and no recording
    qtbot.waitUntil(lambda: not page.is_busy(), timeout=60_000)
    assert workers.SHOWN_ERRORS[n + 1][0] == "Cannot open" and "no recording" in workers.SHOWN_ERRORS[n + 1][1]
    assert page.session is None and not page.fit_button.isEnabled()


def test_closing_or_opening_again_while_reading_is_safe(qtbot, page, demo_dir, tmp_path, monkeypatch):
    from plantreg_gui.gui import workers

    reads = []
    _spy(monkeypatch, Recording, "load", reads, delay_s=0.4)  # a slow disk
    n = len(workers.SHOWN_ERRORS)
    rig, rec = demo_dir / "rig.json", [demo_dir / "recording"]
    page.open(rig, tmp_path / "a.json", rec)
    page.open(rig, tmp_path / "b.json", rec)  # another file while the first is read: the first is dropped
    qtbot.waitUntil(lambda: page.session is not None and not page.is_busy(), timeout=120_000)
    qtbot.wait(200)
    assert page.session.landmarks.path == tmp_path / "b.json"
    assert len(workers.SHOWN_ERRORS) == n and "cancelled" not in page.hint.text()
    # Cancel while reading: the shown session stays
    page.open(rig, tmp_path / "c.json", rec)
    assert page.cancel_button.isEnabled()
    page.cancel_button.click()
    qtbot.waitUntil(lambda: not page.is_busy(), timeout=60_000)
    assert page.session.landmarks.path == tmp_path / "b.json"
    # closing while reading: shutdown stops the read, and what was read is never shown
    page.open(rig, tmp_path / "d.json", rec)
    from stall_probe import LoadControl

    with LoadControl() as control:
        t0 = time.perf_counter()
        page.shutdown()
        took = time.perf_counter() - t0
    assert took < control.allowed(10.0)  # a stop, not a wait for the (0.4 s per call) reads
    qtbot.waitUntil(lambda: not page.is_busy(), timeout=60_000)
    qtbot.wait(200)
    assert page.session.landmarks.path == tmp_path / "b.json"
    assert len(workers.SHOWN_ERRORS) == n


def _refine_threads() -> list[str]:
    return [t.name for t in threading.enumerate() if t.name.startswith("refine")]


def test_refine_runs_in_a_child_process_and_cancel_stops_it(qtbot, page, demo_dir, tmp_path):
    import multiprocessing

    page.open(demo_dir / "rig.json", tmp_path / "landmarks.json", [demo_dir / "recording"])
    qtbot.waitUntil(lambda: page.session is not None and not page.is_busy(), timeout=120_000)
    s = page.session
    rig0 = s.rig.to_dict()
    # only the refinement's own child: an earlier test in the same run may have left a warm
    # calculation process (process_job's pool) alive, as it is meant to stay
    before = set(multiprocessing.active_children())
    page.run_refine()
    assert page.is_busy(include_overlay=False) and page.cancel_button.isEnabled()
    # under way: the cameras are being refined (progress past the preparation, 10 %)
    qtbot.waitUntil(lambda: page.progress.value() >= 150, timeout=120_000)
    threads = _refine_threads()
    children = [c for c in multiprocessing.active_children() if c not in before]
    assert not threads, f"the refinement runs on threads of the GUI's process: {threads}"
    assert children
    t0 = time.perf_counter()
    with qtbot.waitSignal(page._refine_worker.cancelled, timeout=60_000):
        page.cancel_button.click()
    print(f"refine cancelled after {time.perf_counter() - t0:.2f} s")
    qtbot.waitUntil(lambda: not page.is_busy(), timeout=60_000)
    assert not any(c.is_alive() for c in children)
    assert s.rig.to_dict() == rig0 and "Refine cancelled" in page.hint.text()


def test_refine_in_a_child_process_returns_its_result(qtbot, page, demo_dir, tmp_path):
    from plantreg_gui.core.rigfit.refine import RefineParams
    from plantreg_gui.gui.workers import Worker

    page.open(demo_dir / "rig.json", tmp_path / "landmarks.json", [demo_dir / "recording"])
    qtbot.waitUntil(lambda: page.session is not None and not page.is_busy(), timeout=120_000)
    s = page.session
    rig0 = s.rig.to_dict()
    job = s.refine_job(["thermal"], in_process=True,
                       params=RefineParams(levels_deg=(0.4, 0.0), max_points=1000, min_points=500))
    seen, results, errors = [], [], []
    w = Worker(job)
    w.progress.connect(lambda f, m: seen.append(f))
    w.finished.connect(results.append)
    w.failed.connect(lambda msg, det: errors.append(msg))
    w.start()
    qtbot.waitUntil(lambda: not w.is_running(), timeout=300_000)
    assert not errors and results
    result = results[0]
    assert seen and "thermal" in result.report["cameras"]
    page._refine_finished(result)
    assert "refine thermal" in page.report_text.toPlainText()
    s.undo()
    assert s.rig.to_dict() == rig0


def test_session_load_reads_every_recording_and_is_cancellable(demo_dir, tmp_path):
    """The worker's routine (Qt-free): every recording and its depth map read on return (nothing
    left for the GUI thread to read later), a cancel honoured between the reads."""
    from plantreg_gui.core.errors import Cancelled, InputError
    from plantreg_gui.models.landmarks import LandmarkSession
    from plantreg_gui.core.progress import CancelToken, Reporter

    msgs = []
    s = LandmarkSession.load(demo_dir / "rig.json", tmp_path / "lm.json", [demo_dir / "recording"],
                             progress=Reporter(lambda f, m: msgs.append((f, m))))
    assert s.recording_keys and set(s._recordings) == set(s.recording_keys) == set(s._depth_m)
    assert msgs[-1][0] == 1.0 and any("reading recording" in m for _, m in msgs)
    token = CancelToken()
    token.cancel()
    with pytest.raises(Cancelled):
        LandmarkSession.load(demo_dir / "rig.json", tmp_path / "lm.json", [demo_dir / "recording"],
                             progress=Reporter(None, token))
    with pytest.raises(InputError, match="no recording"):
        LandmarkSession.load(demo_dir / "rig.json", tmp_path / "lm.json")
