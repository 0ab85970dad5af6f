"""Hostile inputs, round 3 (issue 22): two plantreg runs writing the same output at once.

Every command that writes takes the one output lock (``plantreg_gui/core/io/lock.py``) before its
long work: a second run that wants the same output is refused with one line naming the output and
the other run's process, exit 1, and writes nothing; the first run is not disturbed. Only
``batch`` refused a concurrent run before; the others ran side by side, the last writer winning.
The promise: docs/errors.md ("Concurrent runs").
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from test_cli_fit_rig import fit_inputs  # noqa: F401 (fixture)
from test_hostile import _env, _write_inputs, tiny_session  # noqa: F401 (fixture)
from test_hostile_round3_paths import _snapshot

PLANTREG = [sys.executable, "-m", "plantreg_gui"]

_HOLDER = """
import sys
from plantreg_gui.core.io.lock import output_lock
with output_lock(*sys.argv[1:]):
    print("held", flush=True)
    sys.stdin.read()
"""


def _lock_of(out: Path) -> Path:
    return out.parent / f".{out.name}.plantreg-lock"


class _Holder:
    """Another process holding the output lock of ``outputs`` (the code a plantreg run uses)."""

    def __init__(self, *outputs: Path):
        self.p = subprocess.Popen([sys.executable, "-c", _HOLDER, *map(str, outputs)], env=_env(),
                                  stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
        assert self.p.stdout.readline().strip() == "held"

    def release(self) -> None:
        self.p.communicate("", timeout=60)
        assert self.p.returncode == 0


def _commands(root: Path, session: Path, lab: Path) -> dict[str, tuple[list[str], Path]]:
    """Every writing command: (argv, the output whose lock it needs)."""
    rig, rec = _write_inputs(root)
    s = root / "session"
    shutil.copytree(session, s)
    cam = ["--camera", "ir=infrared,640x576,f=504,rot=0"]
    return {
        "register": (["register", "--rig", rig, "--recording", rec, "--target", "ir", "--out", root / "out",
                      "--quiet"], root / "out"),
        "batch": (["batch", "--rig", rig, "--target", "ir", "--out", root / "bout", "--workers", "1", "--quiet",
                   rec], root / "bout"),
        "calibrate --out": (["calibrate", s, "--out", root / "cal.json", "--report", root / "rep.json",
                             "--quiet"], root / "cal.json"),
        "calibrate --report": (["calibrate", s, "--out", root / "cal.json", "--report", root / "rep.json",
                                "--quiet"], root / "rep.json"),
        "fit-rig": (["fit-rig", "--rig", lab / "start.json", "--landmarks", lab / "landmarks.json", "--out",
                     root / "fit.json", "--quiet"], root / "fit.json"),
        "rig create": (["rig", "create", root / "new.json", "--depth-camera", "ir", *cam], root / "new.json"),
        "recording create": (["recording", "create", root / "newrec", "--depth", rec / "depth.png"],
                             root / "newrec" / "recording.json"),
        "demo": (["demo", root / "demo", "--quiet"], root / "demo"),
    }


@pytest.mark.parametrize("command", ["register", "batch", "calibrate --out", "calibrate --report", "fit-rig",
                                     "rig create", "recording create", "demo"])
def test_every_writing_command_refuses_an_output_another_run_is_writing(command, tmp_path, tiny_session,
                                                                        fit_inputs):  # noqa: F811
    """Another process holds the output's lock: the command exits 1 with one line naming the
    output and that process, and nothing under the test's folder changes (on the old code every
    command but batch ran and wrote)."""
    lab = tmp_path / "lab"
    shutil.copytree(fit_inputs[0], lab)
    root = tmp_path / "w"
    root.mkdir()
    argv, out = _commands(root, tiny_session, lab)[command]
    holder = _Holder(out)
    try:
        before = _snapshot(tmp_path)
        r = subprocess.run([*PLANTREG, *map(str, argv)], env=_env(), capture_output=True, text=True, timeout=300)
        assert r.returncode == 1, (r.returncode, r.stderr)
        assert "Traceback" not in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr
        assert str(out) in r.stderr and "another plantreg run" in r.stderr, r.stderr
        assert f"process {holder.p.pid}" in r.stderr, r.stderr
        assert _snapshot(tmp_path) == before  # nothing written, the holder's lock file untouched
    finally:
        holder.release()
    assert not _lock_of(out).exists()


def test_two_real_registers_into_one_out(tmp_path):
    """Two real ``plantreg register`` processes into one OUT: the second, started while the first
    holds OUT (the first is paused by SIGSTOP as soon as its lock file names it, so the second
    surely overlaps it), is refused naming OUT and the first's process; the first, resumed, ends
    with exit 0 and a complete output, and no lock file is left."""
    rig, rec = _write_inputs(tmp_path)
    out = tmp_path / "out"
    cmd = [*PLANTREG, "register", "--rig", str(rig), "--recording", str(rec), "--target", "ir", "--out", str(out),
           "--quiet"]
    a = subprocess.Popen(cmd, env=_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        t0 = time.monotonic()
        while time.monotonic() - t0 < 120 and a.poll() is None:
            try:
                if _lock_of(out).read_text().startswith(f"{a.pid} "):
                    break
            except OSError:
                pass
            time.sleep(0.005)
        os.kill(a.pid, signal.SIGSTOP)
        assert a.poll() is None and not out.exists(), "the first run ended before it could be paused"
        b = subprocess.run(cmd, env=_env(), capture_output=True, text=True, timeout=300)
        os.kill(a.pid, signal.SIGCONT)
        _o, err_a = a.communicate(timeout=300)
    finally:
        if a.poll() is None:
            os.kill(a.pid, signal.SIGCONT)
            a.kill()
    assert b.returncode == 1 and f"process {a.pid}" in b.stderr and str(out) in b.stderr, b.stderr
    assert len(b.stderr.strip().splitlines()) == 1 and "Traceback" not in b.stderr
    assert a.returncode == 0, err_a
    assert (out / "summary.json").is_file() and (out / "registered").is_dir()
    assert sorted(p.name for p in tmp_path.iterdir() if p.name.startswith(".")) == []  # no lock, no temporary


def test_a_lock_left_by_a_killed_run_is_taken_over(tmp_path):
    """A run killed with SIGKILL leaves its lock file; the kernel freed its lock, so the next run
    takes it over (not judged by the file's age or a reused process id) and removes it."""
    rig, rec = _write_inputs(tmp_path)
    out = tmp_path / "new.json"
    holder = _Holder(out)
    holder.p.kill()
    holder.p.wait(10)
    assert _lock_of(out).is_file()
    r = subprocess.run([*PLANTREG, "rig", "create", str(out), "--depth-camera", "ir", "--camera",
                        "ir=infrared,640x576,f=504,rot=0"], env=_env(), capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert out.is_file() and not _lock_of(out).exists()


def test_one_output_spelled_two_ways_shares_one_lock(tmp_path):
    """``out`` and a symbolic link to its folder name the same output: one lock."""
    from plantreg_gui.core.io.lock import lock_path

    (tmp_path / "real").mkdir()
    os.symlink("real", tmp_path / "link")
    assert lock_path(tmp_path / "link" / "o.json") == lock_path(tmp_path / "real" / "x" / ".." / "o.json")


def test_an_output_name_near_the_length_limit_still_has_a_lock(tmp_path):
    """A 250-character output name (which plantreg writes) leaves no room for the lock's prefix and
    suffix: its lock file name is shortened, and still differs from a sibling's of the same start."""
    from plantreg_gui.core.io.lock import lock_path, output_lock

    a, b = tmp_path / ("o" * 249 + "a"), tmp_path / ("o" * 249 + "b")
    assert lock_path(a) != lock_path(b) and len(lock_path(a).name) <= 255
    with output_lock(a), output_lock(b):
        assert lock_path(a).is_file() and lock_path(b).is_file()
    assert list(tmp_path.iterdir()) == []
