"""``plantreg``: the command line. Each subcommand lives in its own module with
``add_parser(subparsers)`` and ``run(args) -> int``; errors the user can fix are printed as one
line on stderr with a non-zero exit, never a traceback."""

from __future__ import annotations

import argparse
import importlib
import math
import os
import signal
import sys
import time
from pathlib import Path

from .. import __version__, prefer_one_blas_thread

prefer_one_blas_thread()  # before numpy is first imported (the subcommands import it)
from ..core.errors import Cancelled, PlantregError, printable_streams, quiet_library_notes, show_path
from ..core.io.paths import remember_reads
from ..core import signals
from ..core.signals import Terminated  # noqa: F401 - raised by a terminating signal (docs/errors.md)

SUBCOMMANDS = ("demo", "register", "calibrate", "fit_rig", "rig", "recording", "batch")  # modules NAME_cmd


class StderrProgress:
    """Progress callback printing ``[ 42%] message`` lines to stderr (rate-limited)."""

    def __init__(self, quiet: bool = False):
        self.quiet = quiet
        self._last = ("", -1.0, 0.0)

    def __call__(self, fraction: float, message: str) -> None:
        if self.quiet:
            return
        now = time.monotonic()
        msg, frac, t = self._last
        message = message or msg  # a step's own progress without a label stays under its stage's name
        if message == msg and fraction - frac < 0.05 and now - t < 2.0:
            return
        self._last = (message, fraction, now)
        print(f"[{100 * fraction:3.0f}%] {message}", file=sys.stderr, flush=True)


# ---------------------------------------------------------------------- argument types
# argparse prints "plantreg register: error: argument --seed: ..." and exits 2 for these.
def nonempty_path(text: str) -> Path:
    """A path argument; "" (an unset shell variable) would silently mean the current folder."""
    if text == "":
        raise argparse.ArgumentTypeError("must not be empty (an unset shell variable?)")
    return Path(text)


def finite_float(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not a number") from None
    if not math.isfinite(v):
        raise argparse.ArgumentTypeError(f"must be a finite number, got '{text}'")
    return v


def positive_float(text: str) -> float:
    v = finite_float(text)
    if not v > 0:
        raise argparse.ArgumentTypeError(f"must be positive, got '{text}'")
    return v


def nonneg_int(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not a whole number") from None
    if v < 0 or v >= 2**63:
        raise argparse.ArgumentTypeError(f"must be a whole number from 0 to 2**63 - 1, got '{text}'")
    return v


def _silence_stdio() -> None:
    """Point stdout/stderr at /dev/null: after a reader closed the pipe, the interpreter's own
    flush at exit would otherwise report the broken pipe once more."""
    try:
        null = os.open(os.devnull, os.O_WRONLY)
        for stream in (sys.stdout, sys.stderr):
            try:
                os.dup2(null, stream.fileno())
            except (OSError, ValueError, AttributeError):  # not a file (captured in a test)
                pass
        os.close(null)
    except OSError:  # pragma: no cover - no /dev/null
        pass


def build_parser(argv: list[str] | None = None) -> argparse.ArgumentParser:
    """The command line's parser. With ``argv`` naming a subcommand first (``register ...``), only
    that subcommand's module is imported and its parser built (the others' modules are not
    loaded: start-up of a pipeline step); otherwise (``--help``, an unknown word, no argument)
    every subcommand's, so that the top-level help and errors list them all."""
    p = argparse.ArgumentParser(prog="plantreg", description="Multimodal 3D image registration for plant phenotyping")
    p.add_argument("--version", action="version", version=f"plantreg {__version__}")
    sub = p.add_subparsers(dest="command", metavar="COMMAND", required=True)
    first = argv[0] if argv else ""
    only = first.replace("-", "_") if not first.startswith("-") else ""
    for name in SUBCOMMANDS if only not in SUBCOMMANDS else (only,):
        mod = importlib.import_module(f".{name}_cmd", __name__)
        mod.add_parser(sub)
    if only in SUBCOMMANDS and first not in sub.choices:  # a module's command is named otherwise
        return build_parser()
    return p


class _NamedStdout:
    """``sys.stdout`` while a command runs: an OS error writing it (``>/dev/full``, a full disk
    under a redirect) becomes one line naming standard output, instead of an unnamed "No space
    left on device" (a closed pipe stays a BrokenPipeError: quiet, SIGPIPE's status)."""

    def __init__(self, stream):
        self._stream = stream

    def _guard(self, method: str, *args):
        try:
            return getattr(self._stream, method)(*args)
        except BrokenPipeError:
            raise
        except OSError as e:
            raise PlantregError(f"cannot write to standard output ({e.strerror or e}); output files already "
                                "in place stay") from None

    def write(self, text: str) -> int:
        return self._guard("write", text)

    def flush(self) -> None:
        self._guard("flush")

    def __getattr__(self, name: str):
        return getattr(self._stream, name)


def _memory_import_error(e: ImportError) -> str | None:
    """The one-line message for a library that could not be loaded for lack of address space
    (``ulimit -v``: the loader says "failed to map segment"), None for other import errors."""
    text = str(e)
    if "failed to map segment" in text or "cannot allocate memory" in text.lower():
        return (f"out of memory: a library could not be loaded ({text}); the address-space limit "
                "(ulimit -v) is too low for plantreg")
    return None


class _RecordingStdout:
    """``sys.stdout`` while argparse runs: argparse swallows an OS error writing its help or
    version (``--help >/dev/full`` ended with exit 0 and no help); this remembers it."""

    def __init__(self, stream):
        self._stream, self.error = stream, None

    def write(self, text: str) -> int:
        try:
            return self._stream.write(text)
        except OSError as e:
            self.error = self.error or e
            raise

    def flush(self) -> None:
        try:
            self._stream.flush()
        except OSError as e:
            self.error = self.error or e
            raise

    def __getattr__(self, name: str):
        return getattr(self._stream, name)


def _after_argparse(rc: int, error: OSError | None) -> int:
    """``rc`` once argparse's text (help, version) is flushed to standard output; a reader that
    went away is SIGPIPE's status, a write error (``--help >/dev/full``) one line and exit 1 (the
    help was lost: not 0)."""
    if error is None:
        try:
            sys.stdout.flush()
        except OSError as e:
            error = e
    if isinstance(error, BrokenPipeError):
        _silence_stdio()
        return 128 + signal.SIGPIPE
    if error is not None:
        _silence_stdio_out()
        print(f"plantreg: error: cannot write to standard output ({error.strerror or error})", file=sys.stderr)
        return 1
    return rc


def _silence_stdio_out() -> None:
    """Point stdout at /dev/null after a write error on it, so the interpreter's flush at exit does
    not report it again."""
    try:
        null = os.open(os.devnull, os.O_WRONLY)
        os.dup2(null, sys.stdout.fileno())
        os.close(null)
    except (OSError, ValueError, AttributeError):
        pass


def _open_standard_fds() -> None:
    """A standard file descriptor closed when the program started (``2>&-``, ``<&-``) is opened on
    /dev/null: else the first file opened takes its number, and whatever a library or a child
    process writes to "standard error" lands in that file. A closed stderr is then /dev/null for
    Python too (it was None: ``batch`` died on ``sys.stderr.isatty()`` with an invisible traceback,
    exit 1; other commands printed progress into their results on stdout): the user discarded the
    messages, the exit status still tells."""
    for fd, flags in ((0, os.O_RDONLY), (1, os.O_WRONLY), (2, os.O_WRONLY)):
        try:
            os.fstat(fd)
        except OSError:
            try:
                new = os.open(os.devnull, flags)
                if new != fd:
                    os.dup2(new, fd)
                    os.close(new)
            except OSError:  # pragma: no cover - no /dev/null
                continue
            if fd == 2 and sys.stderr is None:
                sys.stderr = open(2, "w", closefd=False, errors="backslashreplace")


def main(argv: list[str] | None = None) -> int:
    _open_standard_fds()
    if sys.stdout is None:  # started with stdout closed (>&-): results could not be printed
        print("plantreg: error: standard output is closed; plantreg prints its results there (send them to "
              "/dev/null instead: >/dev/null)", file=sys.stderr)
        return 1
    quiet_library_notes()  # and in every child process (signals.child_init)
    # a file name that is not UTF-8 is printed as its own bytes, a character the streams' encoding
    # lacks as an escape (any locale, PYTHONIOENCODING=ascii): never a UnicodeEncodeError
    printable_streams()
    parser = build_parser(list(sys.argv[1:] if argv is None else argv))
    stdout, sys.stdout = sys.stdout, _RecordingStdout(sys.stdout)
    try:
        args = parser.parse_args(argv)
    except SystemExit as e:  # --help, --version, a usage error: what argparse printed must reach its reader
        return _after_argparse(int(e.code) if isinstance(e.code, int) else (0 if e.code is None else 2),
                               sys.stdout.error)
    finally:
        sys.stdout = stdout
    # the words of this command line, for provenance (sys.argv is someone else's when called in-process)
    args.argv = list(sys.argv[1:] if argv is None else argv)
    # SIGTERM, SIGHUP, SIGQUIT, SIGUSR1, SIGALRM, SIGXCPU ... unwind like Ctrl-C (core/signals.py)
    old_handlers = signals.install()
    remember_reads()  # whatever a command reads is one of its inputs: never one of its outputs
    try:
        stdout, sys.stdout = sys.stdout, _NamedStdout(sys.stdout)
        try:
            rc = int(args.run(args) or 0)
            sys.stdout.flush()
        finally:
            sys.stdout = stdout
        return rc
    except Terminated as e:
        print(f"plantreg: terminated by {signal.Signals(e.signum).name}; temporary outputs removed", file=sys.stderr)
        return 128 + e.signum
    except Cancelled:
        print("plantreg: cancelled", file=sys.stderr)
        return 130
    except KeyboardInterrupt:
        print("plantreg: interrupted", file=sys.stderr)
        return 130
    except PlantregError as e:
        print(f"plantreg: error: {' '.join(str(e).split(chr(10)))}", file=sys.stderr)
        return 1
    except MemoryError:
        print("plantreg: error: out of memory", file=sys.stderr)
        return 1
    except ImportError as e:
        if _memory_import_error(e) is None:
            raise
        print(f"plantreg: error: {_memory_import_error(e)}", file=sys.stderr)
        return 1
    except BrokenPipeError:
        # whoever read our output went away (`plantreg ... | head`): stop quietly with SIGPIPE's
        # status, as Unix tools do; outputs are complete (printed after) or never moved into place
        _silence_stdio()
        return 128 + signal.SIGPIPE
    except OSError as e:  # disk full, no permission, a file where a folder should be: name it, no traceback
        where = f"{show_path(e.filename)}: " if e.filename else ""
        print(f"plantreg: error: {where}{e.strerror or e}", file=sys.stderr)
        return 1
    except Exception as e:
        if type(e).__module__.startswith("cv2"):  # an OpenCV refusal we did not foresee: one line, not a page
            from ..core.errors import one_line

            print(f"plantreg: error: OpenCV: {one_line(str(e))}", file=sys.stderr)
            return 1
        raise
    finally:
        signals.uninstall(old_handlers)
        remember_reads(False)


def entry() -> None:
    """The ``plantreg`` program (console script, ``python -m plantreg_gui``): :func:`main`, then
    the exit without the interpreter's teardown of every module and object -- a noticeable wait
    after a ``register`` has finished, for nothing: the
    output files are complete and closed by then. The exit handlers still run (``atexit``:
    temporary folders, logging, process pools, a Dask client) and the standard streams are
    flushed; with a non-daemon thread still running, or if a flush fails (a closed pipe), the
    interpreter exits the ordinary way and reports as usual."""
    import atexit
    import threading

    rc = main()
    if any(not t.daemon for t in threading.enumerate() if t is not threading.main_thread()):
        sys.exit(rc)  # the interpreter waits for such threads
    atexit._run_exitfuncs()  # CPython's own call at exit; it clears them, so they never run twice
    try:
        for stream in (sys.stdout, sys.stderr):
            if stream is not None:  # None: started with the stream closed
                stream.flush()
    except (OSError, ValueError):
        sys.exit(rc)
    os._exit(rc)


if __name__ == "__main__":  # pragma: no cover
    entry()
