"""What makes a batch safe to start and to share its output folder OUT (``plantreg batch``).

* :func:`check_scheduler` asks a ``--scheduler`` who it is (Dask's own handshake and an
  ``identity`` request, within a time limit), before OUT is created: a web server on that port
  used to hang the batch for ever, and one that answered at once made Dask read "HTTP/1.0" as a
  frame length of 3 EiB (``MemoryError``).
* A second run into the same OUT is refused by the lock every writing command takes
  (:func:`plantreg_gui.core.io.lock.output_lock`), instead of the last writer's ``batch.csv`` winning.
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


__all__ = ["BATCH_CSV", "SCHEDULER_TIMEOUT_S", "check_scheduler", "read_csv", "merge_rows",
           "csv_columns", "write_csv"]
