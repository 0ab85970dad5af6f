"""Many recordings, one rig: the engine behind ``plantreg batch`` (no Qt, no printing).

* :func:`plan` names every recording's output folder ``OUT/<recording folder name>`` and refuses
  name clashes before anything runs.
* :func:`run_job` registers one recording into its folder, in exactly ``plantreg register``'s
  layout, and returns one row of ``batch.csv``. It never raises: a bad recording is a row with
  status ``failed`` and the error line. It runs in a worker process (local pool or a Dask
  worker); each process keeps the rig and its cameras' pixel rays between jobs
  (:class:`_WorkerCache`), and Open3D is loaded once per process, not once per recording.
* Resume: every ``summary.json`` written by a batch holds ``inputs.batch_hash``, a hash of
  the rig file, the target, the parameters, the selected outputs and the recording's files
  (``recording.json``'s content, each listed file's size and modification time -- like make
  and rsync, so that a resume does not re-read gigabytes). A job whose folder exists with the
  same hash is ``skipped``; with another hash it fails unless ``overwrite``.
* :func:`run_local` (a process pool) and :func:`run_dask` (a Dask distributed cluster) run the
  jobs and yield rows as they finish; a worker process that dies (killed, out of memory)
  costs its job one more attempt, and after that the job is reported failed -- never lost.
  Output folders are built under a hidden temporary name and moved into place when complete
  (:func:`~plantreg_gui.core.io.imageio.atomic_output_dir`), so a dying worker leaves no
  half-written folder under the final name (only a hidden ``.NAME.*.part`` folder, which
  may be deleted).
* Starting safely and sharing OUT (the scheduler's handshake, OUT's lock, ``batch.csv`` merged
  with earlier runs' rows): :mod:`.batch_guard`.
"""

from __future__ import annotations

import csv
import hashlib
import io
import json
import os
import socket
import time
import unicodedata
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable, Iterator

from ..errors import InputError, said_once
from .batch_guard import BATCH_CSV, write_csv  # noqa: F401 - part of this module's interface

#: Attempts of a job whose worker process died (the first run and one retry).
MAX_ATTEMPTS = 2


@dataclass
class BatchSettings:
    """What every job of one batch shares (picklable; sent to every worker)."""

    rig: str                               # rig file, absolute
    target: str
    out: str                               # OUT, absolute
    params: dict[str, Any] = field(default_factory=dict)   # RegistrationParams fields
    outputs: tuple[str, ...] = ()          # export parts (summary is always written: resume needs it)
    overwrite: bool = False
    tiff_codec: str = "deflate-fp"
    drop_mixed: bool = False               # NaN where a pixel is flagged mixed (pipeline.OutputOptions)


@dataclass
class Job:
    recording: str                         # recording folder as given (absolute)
    name: str                              # output sub-folder name


# ---------------------------------------------------------------------- planning
def read_manifest(path: str | Path) -> list[Path]:
    """Recording folders listed in a text or CSV file: one per line (first CSV column), ``#``
    comments and blank lines ignored, a header ``recording`` skipped; relative paths are taken
    relative to the manifest's folder."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as e:
        raise InputError(f"cannot read the list of recordings ({e})", path) from None
    out: list[Path] = []
    rows = csv.reader(io.StringIO(text))
    for row in rows:
        if not row or not row[0].strip() or row[0].lstrip().startswith("#"):
            continue
        cell = row[0].strip()
        if "\x00" in cell:
            raise InputError(f"line {rows.line_num} holds a NUL character, which no folder name can hold", path)
        if not out and cell.lower() in ("recording", "recordings", "path", "folder"):
            continue
        p = Path(cell).expanduser()
        out.append(p if p.is_absolute() else path.parent / p)
    if not out:
        raise InputError("the list of recordings is empty", path)
    return out


def expand_inputs(items: Iterable[str | Path]) -> list[Path]:
    """Command-line arguments -> recording folders: a file that is not a ``recording.json`` is
    read as a manifest (:func:`read_manifest`), anything else is a recording folder."""
    out: list[Path] = []
    for it in items:
        p = Path(it)
        if p.is_file() and p.name != "recording.json":
            out += read_manifest(p)
        else:
            out.append(p.parent if p.name == "recording.json" else p)
    return out


def plan(recordings: Iterable[str | Path], out: str | Path) -> list[Job]:
    """One :class:`Job` per recording, output folder ``out/<folder name>``. Raises
    :class:`InputError` listing the clashes when two recordings would write the same folder
    (same name, or names equal but for case -- case-insensitive file systems -- or for their
    Unicode spelling: "Ä" as one code point or "A" + a combining accent, which look the same)."""
    jobs: list[Job] = []
    seen: dict[str, Path] = {}
    clashes: list[str] = []
    for r in recordings:
        p = Path(r).absolute()
        name = p.name or "recording"
        if name in (BATCH_CSV,) or name.startswith("."):
            clashes.append(f"{p} (its name '{name}' is reserved in the output folder)")
            continue
        key = unicodedata.normalize("NFC", name).casefold()  # "Ä" typed, or "A" + accent from macOS
        if key in seen:
            if seen[key] == p:
                clashes.append(f"{p} is listed twice")
            else:
                clashes.append(f"{seen[key]} and {p} would both be written to '{name}'")
            continue
        seen[key] = p
        jobs.append(Job(str(p), name))
    if clashes:
        more = f" (and {len(clashes) - 3} more)" if len(clashes) > 3 else ""
        raise InputError("output folder names clash: " + "; ".join(clashes[:3]) + more
                         + "; rename the recording folders or run them in separate batches", out)
    return jobs


# ---------------------------------------------------------------------- hashing
def job_hash(settings: BatchSettings, recording: str | Path) -> str:
    """Hash of what a job's output depends on (see the module docstring); cheap: no image is read."""
    h = hashlib.blake2b(digest_size=16)
    rec = Path(recording)

    def add(tag: str, data: bytes) -> None:
        h.update(tag.encode() + b"\0" + len(data).to_bytes(8, "little") + data)

    add("rig", Path(settings.rig).read_bytes())
    what = {"target": settings.target, "params": settings.params, "outputs": sorted(settings.outputs),
            "tiff_codec": settings.tiff_codec}
    if settings.drop_mixed:  # only when set: outputs of batches made before the option keep their hash
        what["drop_mixed"] = True
    add("settings", json.dumps(what, sort_keys=True).encode())
    manifest = rec / "recording.json"
    add("manifest", manifest.read_bytes())
    from ..io.imageio import read_json_object

    m = read_json_object(manifest, "recording file")  # a hostile manifest is an InputError, not a crash
    images = m.get("images")
    files = [m.get("depth")] + (list(images.values()) if isinstance(images, dict) else [])
    for rel in files:
        if not isinstance(rel, str) or not rel:
            continue  # Recording.load names what is wrong with it
        p = rec / rel
        try:
            st = p.stat()
        except OSError:
            continue  # likewise: a missing or unreadable file is reported by Recording.load
        add("file", f"{rel}\0{st.st_size}\0{st.st_mtime_ns}".encode())
        if p.suffix.lower() == ".hdr":  # the ENVI data file beside the header
            for data in (p.with_suffix(".img"), p.with_suffix(""), p.with_suffix(".raw")):
                if data.is_file():
                    sd = data.stat()
                    add("file", f"{data.name}\0{sd.st_size}\0{sd.st_mtime_ns}".encode())
                    break
    return h.hexdigest()


def existing_hash(folder: Path) -> str | None:
    """``inputs.batch_hash`` of a complete output folder (None if absent or not from a batch)."""
    try:
        s = json.loads((folder / "summary.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if not isinstance(s, dict):
        return None
    files = s.get("files") or []
    if not all((folder / f).is_file() for f in files):  # a user deleted parts: not complete
        return None
    v = (s.get("inputs") or {}).get("batch_hash")
    return v if isinstance(v, str) else None


# ---------------------------------------------------------------------- one job (in a worker)
class _WorkerCache:
    """Per worker process: the rig (by file and modification time) and the pixel-ray caches
    that every Registrar of the same rig shares."""

    key: tuple | None = None
    rig: Any = None
    rays: Any = None


def _rig_for(settings: BatchSettings):
    from ..camera.rig import Rig

    st = os.stat(settings.rig)
    key = (settings.rig, st.st_mtime_ns, st.st_size)
    if _WorkerCache.key != key:
        _WorkerCache.key, _WorkerCache.rig, _WorkerCache.rays = key, Rig.load(settings.rig), None
    return _WorkerCache.rig


def run_job(settings: BatchSettings, job: Job) -> dict[str, Any]:
    """Register one recording into ``OUT/<job.name>``; returns its ``batch.csv`` row. Never raises
    for a bad recording (the row says ``failed`` and why)."""
    t0 = time.perf_counter()
    out = Path(settings.out) / job.name
    row: dict[str, Any] = {"recording": job.recording, "name": job.name, "status": "failed", "error": "",
                           "out": str(out), "files": "", "worker": f"{socket.gethostname()}:{os.getpid()}"}
    try:
        row.update(_run_job(settings, job, out))
    except Exception as e:  # one bad recording never stops the others: report it in its row
        from ..errors import PlantregError

        if isinstance(e, PlantregError):
            row["error"] = said_once(getattr(e, "path", None), getattr(e, "detail", None) or str(e), job.recording)
        elif isinstance(e, MemoryError):
            row["error"] = "out of memory"
        elif isinstance(e, OSError):
            row["error"] = said_once(e.filename, str(e.strerror or e), job.recording)
        else:  # a defect, not a user error: keep the type so it can be reported
            row["error"] = f"internal error ({type(e).__name__}: {e})"
    row["seconds_total"] = round(time.perf_counter() - t0, 3)
    return row


def _run_job(settings: BatchSettings, job: Job, out: Path) -> dict[str, Any]:
    import numpy as np

    from ..registration.params import RegistrationParams
    from .pipeline import OutputOptions, register_recording

    try:
        h: str | None = job_hash(settings, job.recording)
    except (OSError, ValueError):  # a broken recording: Recording.load below says what is wrong
        h = None
    if out.exists() and not settings.overwrite:
        old = existing_hash(out)
        if h is not None and old == h:
            return {"status": "skipped", **_row_from_summary(out)}
        if old is not None:
            raise InputError("output folder exists and was made from other inputs or parameters "
                             "(pass --overwrite to replace it)", out)
        if out.is_dir() and any(out.iterdir()):
            raise InputError("output folder exists and is not a complete batch output "
                             "(pass --overwrite to replace it)", out)
    rig = _rig_for(settings)
    params = RegistrationParams(**{k: (np.asarray(v) if isinstance(v, list) else v)
                                   for k, v in settings.params.items()})
    if _WorkerCache.rays is None:
        _WorkerCache.rays = ({}, {})  # same rig: the same pixel rays in every job of this worker
    if h is None:  # the recording is read first: it raises what is wrong with it
        from ..data.recording import Recording

        Recording.load(job.recording, rig)
        h = job_hash(settings, job.recording)
    what = tuple(dict.fromkeys([*settings.outputs, "summary"]))
    run = register_recording(rig, job.recording, settings.target, out, params,
                             OutputOptions(parts=what, tiff_codec=settings.tiff_codec, drop_mixed=settings.drop_mixed),
                             overwrite=True, encode_early=False, ray_cache=_WorkerCache.rays,
                             inputs={"rig": Path(settings.rig), "recording": Path(job.recording), "batch_hash": h,
                                     "command": "plantreg batch"})
    row = {"status": "done", **{f"seconds_{k}": round(v, 3) for k, v in run.seconds.items()}}
    row.update(_row_from_summary(out))
    return row


def _row_from_summary(out: Path) -> dict[str, Any]:
    """Case shares (percent of target pixels) and written files from a folder's summary.json."""
    try:
        s = json.loads((out / "summary.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}
    row: dict[str, Any] = {"files": ";".join(s.get("files") or [])}
    if s.get("warnings"):  # e.g. an ROI that takes in the ground (core/geometry/roi.py)
        row["warnings"] = " | ".join(s["warnings"])
    for cam, cases in (s.get("cases") or {}).items():
        for entry in cases.values():
            row[f"{cam} {_short(entry.get('code'))} %"] = entry.get("percent")
    for entry in (s.get("areas") or {}).values():
        row[f"area P{entry.get('code')} %"] = entry.get("percent")
    return row


def _short(code: Any) -> str:
    """A case code's short label (:class:`~..registration.cases.Case`), the code itself if unknown."""
    from ..registration.cases import Case

    try:
        return Case(int(code)).short
    except (TypeError, ValueError):
        return str(code)


# ---------------------------------------------------------------------- engines
def skipped_row(settings: BatchSettings, job: Job) -> dict[str, Any] | None:
    """The row of a job whose output is already complete and made from the same inputs and
    parameters (checked in the submitting process: no worker needs to start), else None."""
    out = Path(settings.out) / job.name
    if settings.overwrite or not out.is_dir():
        return None
    try:
        h = job_hash(settings, job.recording)
    except (OSError, ValueError):
        return None
    if existing_hash(out) != h:
        return None
    return {"recording": job.recording, "name": job.name, "status": "skipped", "error": "", "out": str(out),
            "attempts": 0, **_row_from_summary(out)}


def run(settings: BatchSettings, jobs: list[Job], workers: int = 1,
        scheduler: str | None = None) -> Iterator[dict[str, Any]]:
    """Yield one row per job as jobs finish: first the ones to skip, then the others from a
    local pool of ``workers`` processes or, with ``scheduler``, from a Dask cluster."""
    todo = []
    for j in jobs:
        row = skipped_row(settings, j)
        if row is None:
            todo.append(j)
        else:
            yield row
    if not todo:
        return
    if scheduler:
        yield from run_dask(settings, todo, scheduler)
    else:
        yield from run_local(settings, todo, workers)


def _failed_row(job: Job, settings: BatchSettings, error: str, attempts: int) -> dict[str, Any]:
    return {"recording": job.recording, "name": job.name, "status": "failed", "error": error,
            "out": str(Path(settings.out) / job.name), "files": "", "attempts": attempts}


def _preload(workers: int = 1) -> None:
    """Worker start-up: load the libraries once, before the first job is timed; a terminating
    signal to the process group makes the worker remove its partial output (core/signals.py)."""
    import os

    from .. import signals

    signals.child_init()
    from ..export import export  # noqa: F401
    from ..registration import register, sampling  # noqa: F401
    from ..geometry.o3d_core import open3d_core

    if workers >= (os.cpu_count() or 1):
        # the pool's processes already keep every core busy: a second sampling thread for a big
        # cube (sampling.SAMPLE_THREADS) would only add CPU time
        sampling.SAMPLE_THREADS = 1

    open3d_core()


def run_local(settings: BatchSettings, jobs: list[Job], workers: int) -> Iterator[dict[str, Any]]:
    """Run ``jobs`` in a pool of ``workers`` processes; yield rows as jobs finish (any order).

    A worker that dies breaks Python's pool: the pool is rebuilt and every job that had not
    finished is submitted again; a job that was running in a dying pool twice is reported
    failed (it may be what kills the worker, e.g. by running out of memory).
    """
    attempts = {j.name: 0 for j in jobs}
    todo = list(jobs)
    from .. import signals

    ctx = signals.spawn_context()  # no fork of a process with threads
    # the workers are the parallelism: a BLAS thread pool per worker only contends with the others
    # (a 204 x 204 eigen-decomposition for a preview took seconds with 2 workers x 2 BLAS threads)
    threads = str(max(1, (os.cpu_count() or 1) // max(1, workers)))
    saved = {v: os.environ.get(v) for v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")}
    for var, old in saved.items():
        if old is None:
            os.environ[var] = threads  # inherited by the spawned workers (spawned on demand: kept set)
    try:
        yield from _pool_rows(settings, todo, workers, attempts, ctx)
    finally:
        for var, old in saved.items():
            if old is None:
                os.environ.pop(var, None)


def _pool_rows(settings: BatchSettings, todo: list[Job], workers: int, attempts: dict[str, int],
               ctx) -> Iterator[dict[str, Any]]:
    from concurrent.futures import ProcessPoolExecutor

    from .. import signals

    while todo:
        with ProcessPoolExecutor(max_workers=max(1, min(workers, len(todo))), mp_context=ctx,
                                 initializer=_preload, initargs=(workers,)) as pool:
            queue, todo = todo, []
            try:
                broken = yield from _pool_round(settings, pool, queue, todo, workers, attempts)
            except BaseException:
                # a signal, an error, or the caller stopped: the workers remove their partial
                # outputs and end, rather than the pool waiting for their jobs to finish
                signals.stop_pool(pool)
                raise
            todo += queue
            if broken:
                pool.shutdown(wait=False, cancel_futures=True)


def _pool_round(settings: BatchSettings, pool, queue: list[Job], todo: list[Job], workers: int,
                attempts: dict[str, int]):
    """Run ``queue``'s jobs on ``pool`` until it is empty or the pool breaks; jobs to run again
    are appended to ``todo`` (those not started stay in ``queue``). Returns whether it broke."""
    from concurrent.futures import FIRST_COMPLETED, wait
    from concurrent.futures.process import BrokenProcessPool

    # at most one job per worker in flight: when the pool breaks, exactly the jobs that
    # were running lose an attempt, not the ones still waiting
    futures: dict = {}
    broken = False
    while (queue and not broken) or futures:
        while queue and not broken and len(futures) < max(1, workers):
            j = queue.pop(0)
            try:
                futures[pool.submit(run_job, settings, j)] = j
            except BrokenProcessPool:
                broken = True
                queue.insert(0, j)
        if not futures:
            break
        done, _ = wait(set(futures), return_when=FIRST_COMPLETED)
        for f in done:
            j = futures.pop(f)
            try:
                row = f.result()
            except BrokenProcessPool:
                broken = True
                attempts[j.name] += 1
                if attempts[j.name] >= MAX_ATTEMPTS:
                    yield _failed_row(j, settings, "worker process died twice while registering it "
                                      "(killed, or out of memory)", attempts[j.name])
                else:
                    todo.append(j)
                continue
            except Exception as e:  # pragma: no cover - run_job does not raise
                yield _failed_row(j, settings, f"internal error ({type(e).__name__}: {e})", attempts[j.name] + 1)
                continue
            row["attempts"] = attempts[j.name] + 1
            yield row
    return broken


def run_dask(settings: BatchSettings, jobs: list[Job], scheduler: str) -> Iterator[dict[str, Any]]:
    """Run ``jobs`` on the Dask distributed cluster at ``scheduler`` (``tcp://host:8786``);
    yield rows as jobs finish. The workers must see the same file system (same paths).

    Dask itself reschedules the task of a worker that dies; a task whose workers die
    ``distributed.scheduler.allowed-failures`` times (default 3) comes back as ``KilledWorker``
    and is reported failed.
    """
    try:
        from distributed import Client, as_completed
    except ImportError:  # pragma: no cover - the optional extra
        raise InputError("--scheduler needs Dask distributed: pip install 'plantreg[dask]'") from None
    try:
        client = Client(scheduler, timeout="20s")
    except Exception as e:
        raise InputError(f"cannot connect to the Dask scheduler at {scheduler} ({type(e).__name__}: {e})") from None
    with client:
        futures = {}
        for j in jobs:
            # pure=False: a re-run is new work; dask re-runs the task of a worker that dies by itself
            f = client.submit(run_job, settings, j, key=f"plantreg-{j.name}-{os.urandom(4).hex()}", pure=False)
            futures[f] = j
        for f in as_completed(list(futures)):
            j = futures[f]
            try:
                row = f.result()
                row["attempts"] = row.get("attempts", 1)
            except Exception as e:  # KilledWorker, a worker's lost connection
                row = _failed_row(j, settings, f"Dask: {type(e).__name__}: {e}".splitlines()[0], MAX_ATTEMPTS)
            f.release()
            yield row


__all__ = ["BatchSettings", "Job", "plan", "read_manifest", "expand_inputs", "job_hash", "run_job", "run",
           "run_local", "run_dask", "skipped_row", "write_csv", "BATCH_CSV"]
