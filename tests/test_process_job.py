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


def test_the_worker_pool_is_shut_down_before_the_interpreter_tears_down():
    """Left in the module until the interpreter's teardown, the pool's manager-thread weakref
    callback ran after multiprocessing was gone: "Exception ignored in ... weakref_cb ...
    AttributeError" at the exit of a desktop app that had run the wizard (defect 13 of issue 21;
    seen in the frozen bundle). The pool must be gone by the time the exit handlers registered
    before it have run (they run last)."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    code = ("import atexit, sys\n"
            "from plantreg_gui.core.jobs import process_job\n"
            "atexit.register(lambda: print('pool at teardown:', 'pool' in process_job._state, flush=True))\n"
            "if __name__ == '__main__':\n"
            "    from plantreg_gui.core.jobs.process_job import run_in_process\n"
            "    import test_process_job as t\n"
            "    print('result', run_in_process(t._square, 7), flush=True)\n")
    here = Path(__file__).resolve().parent
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(here.parent), str(here)])}
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, env=env)
    assert r.returncode == 0, r.stderr
    assert "result 49" in r.stdout
    assert "pool at teardown: False" in r.stdout, r.stdout
    assert "Exception ignored" not in r.stderr, r.stderr
