"""Hostile inputs, round 3 (issue 22): batch orchestration, signals to a process group, concurrent runs.

Each test builds what it needs: a fake "scheduler" (an HTTP server or a chatty server on a free
port), a second batch into the same OUT, another batch holding OUT's lock, a signal sent at the
moment a temporary output is seen on disk (found by polling), a CPU-time limit reached while
writing, a signal delivered to another thread during calibrate's final renames. The promise
and its limits: docs/errors.md ("Signals" and "Concurrent runs").
"""

from __future__ import annotations

import csv
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import textwrap
import threading
import time
from pathlib import Path

import pytest

from plantreg_gui import cli
from test_hostile import (_env, _no_leftovers, _write_inputs, held_env, signal_while_held,  # noqa: F401 - a fixture
                          tiny_session, wait_for_hold)

ROOT = Path(__file__).resolve().parents[1]
PLANTREG = [sys.executable, "-m", "plantreg_gui"]


def _rows(out: Path) -> dict[str, dict[str, str]]:
    with (out / "batch.csv").open(encoding="utf-8", newline="") as f:
        return {r["name"]: r for r in csv.DictReader(f)}


def _leftovers(folder: Path) -> list[str]:
    """Temporary outputs and lock files anywhere under ``folder``."""
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*")
                  if ".part" in p.name or ".old" in p.name or p.name.endswith("lock"))


def _lock_of(out: Path) -> Path:
    """The lock file of output OUT: ``.OUT.plantreg-lock`` beside it (docs/errors.md names it)."""
    return out.parent / f".{out.name}.plantreg-lock"


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class _FakeServer:
    """A TCP server on a free port, on a thread: ``mode`` "silent" reads and never answers (an HTTP
    server waiting for a request line), "http" answers every connection with an HTTP error at once."""

    def __init__(self, mode: str):
        self.mode = mode
        self.sock = socket.socket()
        self.sock.bind(("127.0.0.1", 0))
        self.sock.listen(8)
        self.port = self.sock.getsockname()[1]
        self.conns: list[socket.socket] = []
        self._stop = False
        self.thread = threading.Thread(target=self._serve, daemon=True)
        self.thread.start()

    def _serve(self) -> None:
        self.sock.settimeout(0.2)
        while not self._stop:
            try:
                c, _ = self.sock.accept()
            except OSError:
                continue
            self.conns.append(c)
            if self.mode == "http":
                c.sendall(b"HTTP/1.0 400 Bad Request\r\nContent-Type: text/html\r\n\r\n<html>bad request</html>")

    def close(self) -> None:
        self._stop = True
        self.thread.join(2)
        for c in self.conns:
            c.close()
        self.sock.close()


def _batch(rig, out, *recs, extra=(), timeout=120) -> subprocess.CompletedProcess:
    return subprocess.run([*PLANTREG, "batch", "--rig", str(rig), "--target", "ir", "--out", str(out), "--quiet",
                           *extra, *map(str, recs)], env=_env(), capture_output=True, text=True, timeout=timeout)


# ---------------------------------------------------------------------- batch --scheduler
@pytest.mark.parametrize("kind", ["http-silent", "http-answers", "nothing-listens"])
def test_a_scheduler_that_is_not_dask_is_refused_before_out_exists(tmp_path, kind):
    """An HTTP server (silent, or answering at once: Dask read "HTTP/1.0" as a frame length of
    3 EiB) or a closed port as ``--scheduler``: one line naming the address, exit 1, within the
    handshake's time limit, and no OUT (it used to hang for ever, say MemoryError, leave OUT)."""
    rig, rec = _write_inputs(tmp_path)
    server = None
    if kind == "nothing-listens":
        port = _free_port()
    else:
        server = _FakeServer("silent" if kind == "http-silent" else "http")
        port = server.port
    out = tmp_path / "out"
    try:
        r = _batch(rig, out, rec, extra=("--scheduler", f"tcp://127.0.0.1:{port}"), timeout=90)
    finally:
        if server is not None:
            server.close()
    assert r.returncode == 1, r.stderr
    err = r.stderr.strip()
    assert len(err.splitlines()) == 1 and f"127.0.0.1:{port}" in err and "Dask" in err, err
    assert "Traceback" not in err and "MemoryError" not in err and "EiB" not in err, err
    assert not os.path.lexists(out)


def test_a_real_scheduler_passes_the_handshake(tmp_path):
    """The check accepts a real Dask scheduler (what it is there for) and says it is one."""
    from plantreg_gui.core.pipeline import batch_guard

    sf = tmp_path / "scheduler.json"
    p = subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_scheduler", "--host", "127.0.0.1", "--port",
                          "0", "--no-dashboard", "--scheduler-file", str(sf)], env=_env(),
                         stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    try:
        t0 = time.monotonic()
        while not (sf.is_file() and sf.read_text().strip()) and time.monotonic() - t0 < 90:
            time.sleep(0.1)
        addr = json.loads(sf.read_text())["address"]
        assert batch_guard.check_scheduler(addr)["type"] == "Scheduler"
    finally:
        os.killpg(p.pid, signal.SIGTERM)
        p.wait(30)


# ---------------------------------------------------------------------- batch.csv of several runs
def test_a_second_batch_into_the_same_out_keeps_the_first_runs_rows(tmp_path, capsys):
    """Run 1: rec_a into OUT; run 2: rec_b into OUT -> batch.csv lists both (it used to hold only
    rec_b's row while OUT/rec_a stayed); run 3: rec_a again with --overwrite -> its row replaced,
    not doubled; rec_b's row kept as it was."""
    rig, rec = _write_inputs(tmp_path)
    a, b = rec.rename(tmp_path / "rec_a"), tmp_path / "rec_b"
    shutil.copytree(a, b)
    out = tmp_path / "out"
    base = ["batch", "--rig", str(rig), "--target", "ir", "--out", str(out), "--workers", "1", "--quiet"]
    assert cli.main([*base, str(a)]) == 0
    first = _rows(out)["rec_a"]
    assert cli.main([*base, str(b)]) == 0
    rows = _rows(out)
    assert list(rows) == ["rec_a", "rec_b"] and rows["rec_a"] == first
    assert rows["rec_b"]["status"] == "done" and (out / "rec_b" / "summary.json").is_file()
    assert cli.main([*base, "--overwrite", str(a)]) == 0
    rows2 = _rows(out)
    assert list(rows2) == ["rec_a", "rec_b"] and rows2["rec_b"] == rows["rec_b"]
    assert rows2["rec_a"]["status"] == "done" and rows2["rec_a"]["worker"] != "" and rows2["rec_a"] != first
    assert "earlier" in capsys.readouterr().out
    assert sorted(p.name for p in out.iterdir()) == ["batch.csv", "rec_a", "rec_b"]  # no lock file left


def test_a_batch_csv_that_is_not_a_batch_table_is_not_replaced(tmp_path, capsys):
    rig, rec = _write_inputs(tmp_path)
    out = tmp_path / "out"
    out.mkdir()
    (out / "batch.csv").write_text("my,own\nnotes,here\n")
    code = cli.main(["batch", "--rig", str(rig), "--target", "ir", "--out", str(out), "--workers", "1", "--quiet",
                     str(rec)])
    err = capsys.readouterr().err
    assert code == 1 and str(out / "batch.csv") in err and len(err.strip().splitlines()) == 1, err
    assert (out / "batch.csv").read_text() == "my,own\nnotes,here\n" and not (out / "rec").exists()


# ---------------------------------------------------------------------- concurrent runs into one OUT
_HOLDER = """
import fcntl, os, sys, time
fd = os.open(sys.argv[1], os.O_RDWR | os.O_CREAT, 0o644)
fcntl.flock(fd, fcntl.LOCK_EX)
os.write(fd, f"{os.getpid()} otherhost\\n".encode())
print("held", flush=True)
time.sleep(600)
"""


def test_a_concurrent_batch_into_the_same_out_is_refused_and_a_stale_lock_is_taken_over(tmp_path, capsys):
    """Another run holds OUT's lock: this one is refused with one line naming OUT and the holder,
    and writes nothing (it used to run, the last writer's batch.csv winning). Once the holder is
    killed (SIGKILL: no clean-up, its lock file stays), the lock is free -- known by the kernel's
    lock, not by the file's age -- and the next batch runs and removes the lock file."""
    rig, rec = _write_inputs(tmp_path)
    out = tmp_path / "out"
    out.mkdir()
    holder = subprocess.Popen([sys.executable, "-c", _HOLDER, str(_lock_of(out))], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        base = ["batch", "--rig", str(rig), "--target", "ir", "--out", str(out), "--workers", "1", "--quiet"]
        code = cli.main([*base, str(rec)])
        err = capsys.readouterr().err
        assert code == 1 and str(out) in err and "another plantreg run" in err and str(holder.pid) in err, err
        assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
        assert list(out.iterdir()) == [] and _lock_of(out).is_file()  # nothing written, the holder's lock kept
    finally:
        holder.kill()
        holder.wait(10)
    assert _lock_of(out).is_file()  # stale: its process is gone
    assert cli.main([*base, str(rec)]) == 0
    assert _rows(out)["rec"]["status"] == "done"
    assert sorted(p.name for p in out.iterdir()) == ["batch.csv", "rec"] and not _lock_of(out).exists()


# ---------------------------------------------------------------------- signals
def _wait_for_part(folder: Path, pattern: str, proc: subprocess.Popen, timeout: float = 300) -> Path | None:
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout and proc.poll() is None:
        found = next(iter(folder.glob(pattern)), None) if folder.is_dir() else None
        if found is not None:
            return found
        time.sleep(0.01)
    return None


@pytest.fixture(scope="module")
def two_recordings(demo_dir, tmp_path_factory):
    """Two copies of the demo recording (640 x 576 target: writing takes long enough to be caught)."""
    root = tmp_path_factory.mktemp("round3")
    recs = []
    for name in ("rec01", "rec02"):
        shutil.copytree(demo_dir / "recording", root / name)
        recs.append(root / name)
    return demo_dir / "rig.json", recs


def test_a_second_batch_while_the_first_writes_is_refused(two_recordings, tmp_path):
    """Batch A is writing into OUT (held at its worker's first output, :func:`test_hostile.held_env`)
    when batch B is started into the same OUT: B is refused with one line naming OUT and A's
    process, and writes nothing; A, let go, ends normally with both rows and no lock file left (B
    used to run too, the last writer's batch.csv winning)."""
    rig, recs = two_recordings
    work = tmp_path / "work"
    work.mkdir()
    out = work / "out"
    cmd = [*PLANTREG, "batch", "--rig", str(rig), "--target", "ir", "--out", str(out), "--workers", "1", "--quiet"]
    env, hold, release = held_env(tmp_path, release=True)
    a = subprocess.Popen([*cmd, *map(str, recs)], env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        wait_for_hold(hold, a)
        b = subprocess.run([*cmd, str(recs[0])], env=_env(), capture_output=True, text=True, timeout=300)
        release.touch()
        _o, err_a = a.communicate(timeout=300)
    finally:
        if a.poll() is None:
            a.kill()
    assert b.returncode == 1 and "another plantreg run" in b.stderr and f"process {a.pid}" in b.stderr, b.stderr
    assert str(out) in b.stderr and len(b.stderr.strip().splitlines()) == 1
    assert a.returncode == 0, err_a
    assert list(_rows(out)) == ["rec01", "rec02"] and {r["status"] for r in _rows(out).values()} == {"done"}
    assert _leftovers(work) == []


def test_sigterm_to_the_batch_process_group_leaves_no_part(two_recordings, tmp_path):
    """SIGTERM to the whole process group (systemd, Slurm), sent while a worker writes (held at its
    first output, :func:`test_hostile.held_env`): every process removes what it was writing (it used
    to leave ``.rec02.XXXX.part`` with a partial TIFF), exit 143, no traceback, no lock file."""
    rig, recs = two_recordings
    work = tmp_path / "work"
    work.mkdir()
    out = work / "out"
    p, err = signal_while_held(["batch", "--rig", str(rig), "--target", "ir", "--out", str(out), "--workers", "1",
                                "--quiet", *map(str, recs)], tmp_path, signal.SIGTERM, group=True)
    time.sleep(0.5)  # a worker that outlived its parent would still be writing now
    assert p.returncode == 128 + signal.SIGTERM, (p.returncode, err)
    assert "Traceback" not in err
    assert _leftovers(work) == [], _leftovers(work)


def _register_cmd(rig, rec, out) -> list[str]:
    return [*PLANTREG, "register", "--rig", str(rig), "--recording", str(rec), "--target", "ir", "--out", str(out),
            "--quiet"]


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGQUIT, signal.SIGUSR1, signal.SIGALRM],
                         ids=lambda s: signal.Signals(s).name)
def test_signal_to_register_while_it_writes_leaves_nothing(two_recordings, tmp_path, sig):
    """SIGTERM, SIGQUIT, SIGUSR1 and SIGALRM to register's process group while it writes (held at
    its first output, :data:`test_hostile.HELD`): exit 128 + signal, no OUT, nothing hidden beside it
    (SIGQUIT, SIGUSR1 and SIGALRM used to end it on the spot, leaving ``.out.XXXX.part``)."""
    rig, recs = two_recordings
    work = tmp_path / "work"
    work.mkdir()
    out = work / "out"
    p, err = signal_while_held(_register_cmd(rig, recs[0], out)[len(PLANTREG):], tmp_path, sig, group=True)
    assert p.returncode == 128 + sig, (p.returncode, err)
    assert "Traceback" not in err and "core dumped" not in err
    assert sorted(x.name for x in work.iterdir()) == [], list(work.iterdir())


def test_cpu_time_limit_reached_while_writing_leaves_nothing(two_recordings, tmp_path):
    """``ulimit -S -t``: the soft CPU limit is lowered to what register has used by the time its
    ``.out.XXXX.part`` appears, so SIGXCPU comes while it writes (and again every CPU second):
    exit 128 + SIGXCPU, nothing left (it used to dump core and leave ``.out.XXXX.part``)."""
    import resource

    rig, recs = two_recordings
    out = tmp_path / "out"
    p = subprocess.Popen(_register_cmd(rig, recs[0], out), env=_env(), stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True)
    part = _wait_for_part(tmp_path, ".out.*", p)
    assert part is not None
    with open(f"/proc/{p.pid}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    used = (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    resource.prlimit(p.pid, resource.RLIMIT_CPU, (max(1, int(used)), resource.RLIM_INFINITY))
    _o, err = p.communicate(timeout=120)
    assert p.returncode == 128 + signal.SIGXCPU, (p.returncode, err)
    assert "Traceback" not in err
    assert sorted(x.name for x in tmp_path.iterdir()) == []


_CALIBRATE_RENAMES = """
import os, signal, sys, threading, time
from plantreg_gui.core.io import imageio
from plantreg_gui.cli import main

other = threading.Thread(target=time.sleep, args=(60,), daemon=True)  # a thread that may take the signal
other.start()
real = os.replace
sent = []

def replace(src, dst):
    real(src, dst)
    if ".old" in str(dst) and not sent:  # the first file moved aside: mid-transaction
        sent.append(1)
        signal.pthread_kill(other.ident, signal.SIGTERM)  # the kernel chose another thread
        time.sleep(0.2)

imageio.os.replace = replace
sys.exit(main(sys.argv[1:]))
"""


def test_sigterm_during_calibrates_final_renames_leaves_a_whole_set(tiny_session, tmp_path):
    """calibrate --overwrite is moving the new rig, report and tables into place when SIGTERM
    arrives -- delivered to another of its threads, as the kernel may choose. The renames finish
    first (signals are held on every thread, not only on the one renaming), then the command stops
    with 143: the new set is whole, and no ``.rig.XXXX.old.json`` / ``.r_*.old.csv`` is left (it
    used to be, 1 in 9 tries, while printing "temporary outputs removed")."""
    out, rep = tmp_path / "rig.json", tmp_path / "r.json"
    assert cli.main(["calibrate", str(tiny_session), "--out", str(out), "--report", str(rep), "--quiet"]) == 0
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    r = subprocess.run([sys.executable, "-c", _CALIBRATE_RENAMES, "calibrate", str(tiny_session), "--out", str(out),
                        "--report", str(rep), "--quiet", "--overwrite"], env=_env(), capture_output=True, text=True,
                       timeout=300)
    assert r.returncode == 128 + signal.SIGTERM, (r.returncode, r.stderr)
    assert "Traceback" not in r.stderr
    after = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    assert sorted(after) == sorted(before), sorted(after)  # no .old, no .part
    prov = json.loads(after["rig.json"])["calibration"]
    assert prov != json.loads(before["rig.json"])["calibration"] or after == before  # one whole set, old or new


def test_deferred_section_on_a_worker_thread_holds_the_signal():
    """The mechanism itself: a worker thread in a deferred section when SIGTERM arrives; the main
    thread (where Python runs handlers) gets :class:`Terminated` only after the section ended, and
    no new section starts once the process is terminating."""
    from plantreg_gui.core import signals

    old = signals.install()
    events: list[str] = []
    inside = threading.Event()

    def work() -> None:
        with signals.deferred():
            inside.set()
            os.kill(os.getpid(), signal.SIGTERM)
            time.sleep(0.3)
            events.append("section done")
        try:
            with signals.deferred():
                events.append("second section")
        except signals.Terminated:
            events.append("second refused")

    try:
        t = threading.Thread(target=work)
        with pytest.raises(signals.Terminated) as e:
            t.start()
            inside.wait(10)
            for _ in range(200):
                time.sleep(0.01)
            raise AssertionError("no Terminated")
        events.append("main terminated")
        t.join(10)
    finally:
        signals.uninstall(old)
    assert e.value.signum == signal.SIGTERM and e.value.code == 128 + signal.SIGTERM
    assert events[0] == "section done" and sorted(events[1:]) == ["main terminated", "second refused"], events


def test_a_signal_while_the_staged_tiffs_are_put_away_leaves_no_folder(tmp_path):
    """A terminating signal that lands while register leaves its staged-TIFF context normally (the
    run's end, waiting for the encoder thread) used to skip the removal of the hidden
    ``.out.XXXX.part`` folder (SIGALRM beside two CPU hogs); the signal still ends the run."""
    from plantreg_gui.core.export.tiffs import EarlyTiffs
    from plantreg_gui.core.signals import Terminated

    early = EarlyTiffs(tmp_path / "out")
    early.__enter__()
    assert [p.name.startswith(".out.") for p in tmp_path.iterdir()] == [True]
    real, calls = early._pool.shutdown, []

    def shutdown(*a, **k):  # the signal's handler raises on the main thread during the first wait
        calls.append(k)
        if len(calls) == 1:
            raise Terminated(signal.SIGALRM)
        return real(*a, **k)

    early._pool.shutdown = shutdown
    with pytest.raises(Terminated):
        early.__exit__(None, None, None)
    assert list(tmp_path.iterdir()) == []
