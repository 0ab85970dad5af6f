"""core.jobs.process_job.call_in_process: result, progress, errors and cancellation cross the process boundary."""

from __future__ import annotations

import threading
import time

import pytest

from plantreg_gui.core.errors import Cancelled, InputError, PlantregError
from plantreg_gui.core.jobs.process_job import call_in_process
from plantreg_gui.core.progress import CancelToken, Reporter


def _square(x, progress):
    progress(0.5, "half")
    time.sleep(0.1)  # let the throttled message through
    progress(0.9, "nearly")
    return x * x


def _fails(progress):
    raise InputError("bad thing", "somewhere.json")


def _bug(progress):
    raise ZeroDivisionError("oops")


def _forever(progress):
    while True:
        time.sleep(0.01)
        progress.check()


def test_result_and_progress():
    seen = []
    assert call_in_process(_square, 7, progress=Reporter(lambda f, m: seen.append((f, m)))) == 49
    assert (0.5, "half") in seen


def test_errors_keep_their_message():
    with pytest.raises(PlantregError, match="somewhere.json.*bad thing|bad thing"):
        call_in_process(_fails)
    with pytest.raises(RuntimeError, match="ZeroDivisionError: oops"):
        call_in_process(_bug)


def test_cancel_terminates_the_child():
    token = CancelToken()
    threading.Timer(1.0, token.cancel).start()
    t0 = time.monotonic()
    with pytest.raises(Cancelled):
        call_in_process(_forever, progress=Reporter(None, token))
    assert time.monotonic() - t0 < 30
