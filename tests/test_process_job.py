"""core/jobs/process_job.py: a routine in the worker process keeps the Reporter contract (result,
user errors, progress, cancel) of a routine on a thread."""

from __future__ import annotations

import threading
import time

import pytest


def _square(x, progress=None):
    progress(0.5, "half")
    return x * x


def _bad(progress=None):
    from plantreg_gui.core.errors import InputError

    raise InputError("not a rig file", "/data/x.json")


def _forever(progress=None):
    while True:  # stops only through the Reporter (cancel)
        progress(0.5, "looping")
        time.sleep(0.01)


def test_result_progress_errors_and_cancel():
    from plantreg_gui.core.errors import Cancelled, InputError
    from plantreg_gui.core.jobs.process_job import run_in_process
    from plantreg_gui.core.progress import Reporter

    seen = []
    assert run_in_process(_square, 7, progress=Reporter(lambda f, m: seen.append((f, m)))) == 49
    assert (0.5, "half") in seen
    with pytest.raises(InputError, match="x.json: not a rig file"):
        run_in_process(_bad)
    rep = Reporter()
    threading.Timer(1.0, rep.cancel.cancel).start()
    with pytest.raises(Cancelled):
        run_in_process(_forever, progress=rep)
    assert run_in_process(_square, 3) == 9  # the process serves the next job
