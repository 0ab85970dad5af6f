"""What makes a batch safe to start and to share its output folder OUT (``plantreg batch``).

* :func:`check_scheduler` asks a ``--scheduler`` who it is (Dask's own handshake and an
  ``identity`` request, within a time limit), before OUT is created: a web server on that port
  used to hang the batch for ever, and one that answered at once made Dask read "HTTP/1.0" as a
  frame length of 3 EiB (``MemoryError``).
* :class:`OutputLock` holds ``OUT/.plantreg-batch.lock`` for a whole run, so that a second run
  into the same OUT is refused instead of the last writer's ``batch.csv`` winning.
* :func:`read_csv`, :func:`merge_rows`, :func:`write_csv`: ``batch.csv`` keeps the rows of earlier
  runs into OUT (a recording run again gets its new row).

No Qt, no printing.
"""

from __future__ import annotations

import csv
import io
import os
import socket
from pathlib import Path
from typing import Any

from ..errors import InputError

BATCH_CSV = "batch.csv"
#: The lock file held in OUT while a batch writes there (:class:`OutputLock`).
LOCK_NAME = ".plantreg-batch.lock"
#: Seconds a Dask scheduler has to answer :func:`check_scheduler`.
SCHEDULER_TIMEOUT_S = 10.0
#: Columns of batch.csv before the per-camera case shares.
CSV_COLUMNS = ("recording", "name", "status", "error", "out", "files", "seconds_total", "seconds_read",
               "seconds_register", "seconds_write", "attempts", "worker")


def check_scheduler(address: str, timeout: float | None = None) -> dict[str, Any]:
    """Ask the Dask scheduler at ``address`` (``tcp://host:8786``) who it is, within ``timeout``
    seconds (default :data:`SCHEDULER_TIMEOUT_S`) in all (connection, Dask's handshake, an ``identity`` request); returns its answer.
    Raises :class:`InputError` saying why when nothing answers, something else answers (a web
    server, a dashboard: Dask would read its reply's first bytes as a frame length of exabytes) or
    the answer is not a scheduler's. Runs on a daemon thread, so nothing the peer does can hang us."""
    import asyncio
    import threading

    timeout = SCHEDULER_TIMEOUT_S if timeout is None else timeout
    try:
        from distributed.comm import connect
    except ImportError:  # pragma: no cover - the optional extra
        raise InputError("--scheduler needs Dask distributed: pip install 'plantreg[dask]'") from None
    hint = "give the scheduler's address, e.g. tcp://host:8786 (not its dashboard)"

    try:
        from distributed.comm.addressing import parse_address, parse_host_port

        scheme, loc = parse_address(address)
        host, port = parse_host_port(loc) if scheme in ("tcp", "tls") else (None, None)
    except (ValueError, TypeError) as e:
        raise InputError(f"--scheduler {address}: not an address ({str(e).splitlines()[0]}); {hint}") from None
    if host is not None:  # refused or unknown host: said at once (Dask's connect retries until its timeout)
        if not port:
            raise InputError(f"--scheduler {address}: no port given; {hint}")
        try:
            socket.create_connection((host, port), timeout=timeout).close()
        except socket.timeout:
            raise InputError(f"--scheduler {address}: no answer within {timeout:g} s; {hint}") from None
        except OSError as e:
            raise InputError(f"--scheduler {address}: cannot reach a Dask scheduler ({e.strerror or e}); {hint}") from None

    async def probe() -> Any:
        comm = await connect(address, timeout=timeout)
        try:
            await comm.write({"op": "identity", "reply": True})
            return await comm.read()
        finally:
            comm.abort()

    box: dict[str, Any] = {}

    def target() -> None:
        try:
            box["reply"] = asyncio.run(asyncio.wait_for(probe(), timeout))
        except BaseException as e:  # noqa: BLE001 - reported below, whatever it is
            box["error"] = e

    t = threading.Thread(target=target, name="plantreg-scheduler-check", daemon=True)
    t.start()
    t.join(timeout + 5.0)
    e = box.get("error")
    if t.is_alive() or isinstance(e, (asyncio.TimeoutError, TimeoutError)):
        raise InputError(f"--scheduler {address}: no Dask scheduler answered within {timeout:g} s; {hint}")
    if isinstance(e, (OSError, ConnectionError)) or type(e).__name__ == "CommClosedError":
        why = getattr(e, "strerror", None) or str(e).split(":")[-1].strip() or type(e).__name__
        if "refused" in str(e).lower():
            why = "connection refused (nothing listens there)"
        raise InputError(f"--scheduler {address}: cannot reach a Dask scheduler ({why}); {hint}")
    if isinstance(e, ValueError) and "address" in str(e).lower():
        raise InputError(f"--scheduler {address}: not an address ({str(e).splitlines()[0]}); {hint}")
    if e is not None:  # MemoryError, a decoding error: the peer does not speak Dask's protocol
        raise InputError(f"--scheduler {address}: the server there does not speak Dask's protocol; {hint}")
    reply = box.get("reply")
    if not isinstance(reply, dict) or reply.get("type") != "Scheduler":
        raise InputError(f"--scheduler {address}: the server there is not a Dask scheduler "
                         f"({str(reply.get('type')) if isinstance(reply, dict) else 'unexpected answer'}); {hint}")
    return reply


class OutputLock:
    """``OUT/.plantreg-batch.lock``, held with ``fcntl.flock`` while one batch writes into OUT.

    A second batch into the same OUT finds the lock taken and is refused (:class:`InputError`
    naming the holder's process). The kernel releases the lock when its process ends however it
    ends, so a lock file left by a killed run is recognised as free (by the lock, not by its age
    or a pid that may have been reused) and taken over. Released and removed on every exit
    path of the run (an exception, a signal). A context manager."""

    def __init__(self, out: str | Path):
        self.path = Path(out) / LOCK_NAME
        self._fd: int | None = None

    def __enter__(self) -> "OutputLock":
        import fcntl

        for _ in range(50):
            self.path.parent.mkdir(parents=True, exist_ok=True)
            fd = os.open(self.path, os.O_RDWR | os.O_CREAT | getattr(os, "O_CLOEXEC", 0), 0o644)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                try:
                    holder = os.read(fd, 200).decode("utf-8", "replace").split()
                finally:
                    os.close(fd)
                who = f" (process {holder[0]} on {holder[1]})" if len(holder) >= 2 else ""
                raise InputError(f"another plantreg batch{who} is writing into this folder; wait for it to end, "
                                 "or choose another --out", self.path.parent) from None
            except BaseException:
                os.close(fd)
                raise
            try:  # the previous holder may have removed the file between our open and our lock
                same = os.fstat(fd).st_ino == os.stat(self.path).st_ino
            except FileNotFoundError:
                same = False
            if not same:
                os.close(fd)
                continue
            os.ftruncate(fd, 0)
            os.write(fd, f"{os.getpid()} {socket.gethostname()}\n".encode())
            self._fd = fd
            return self
        raise InputError("could not take the batch lock (its file keeps being replaced)", self.path)  # pragma: no cover

    def __exit__(self, *exc) -> None:
        if self._fd is None:
            return
        try:
            self.path.unlink(missing_ok=True)  # while still holding it: nobody else has it now
        finally:
            os.close(self._fd)
            self._fd = None


# ---------------------------------------------------------------------- the table
def read_csv(path: str | Path) -> list[dict[str, Any]]:
    """The rows of an existing ``batch.csv`` ([] if there is none). Raises :class:`InputError`
    when the file is not a batch table (it would be replaced by this run's rows otherwise)."""
    path = Path(path)
    if not os.path.lexists(path):
        return []
    try:
        with open(path, encoding="utf-8", newline="") as f:
            reader = csv.DictReader(f)
            rows = [dict(r) for r in reader]
            fields = reader.fieldnames or []
    except (OSError, UnicodeDecodeError, csv.Error, ValueError) as e:
        raise InputError(f"cannot read the existing batch table ({getattr(e, 'strerror', None) or e}); move it "
                         "away or choose another --out", path) from None
    if "name" not in fields or "status" not in fields or any(not r.get("name") for r in rows):
        raise InputError("the existing batch table has no 'name' and 'status' columns (not a plantreg batch.csv); "
                         "move it away or choose another --out", path)
    return rows


def merge_rows(old: list[dict[str, Any]], new: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """``old`` rows (an earlier run's batch.csv) with ``new`` ones merged in by output name: a
    recording run again replaces its row in place, other new rows follow in their order."""
    by_name = {r["name"]: r for r in new}
    merged = [by_name.pop(r["name"], r) for r in old]
    return merged + [r for r in new if r["name"] in by_name]


def csv_columns(rows: list[dict[str, Any]]) -> list[str]:
    extra: list[str] = []
    for r in rows:
        extra += [k for k in r if k not in CSV_COLUMNS and k not in extra]
    return [*CSV_COLUMNS, *extra]


def write_csv(path: str | Path, rows: list[dict[str, Any]]) -> None:
    """``batch.csv`` (atomically): one row per recording, in the order given."""
    from ..io.imageio import atomic_write_text

    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=csv_columns(rows), extrasaction="ignore", lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({k: ("" if v is None else v) for k, v in r.items()})
    atomic_write_text(path, buf.getvalue())


__all__ = ["BATCH_CSV", "LOCK_NAME", "SCHEDULER_TIMEOUT_S", "check_scheduler", "OutputLock", "read_csv", "merge_rows",
           "csv_columns", "write_csv"]
