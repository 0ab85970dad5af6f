"""``plantreg``: the command line. Each subcommand lives in its own module with
``add_parser(subparsers)`` and ``run(args) -> int``; errors the user can fix are printed as one
line on stderr with a non-zero exit, never a traceback."""

from __future__ import annotations

import argparse
import importlib
import sys
import time

from .. import __version__
from ..core.errors import Cancelled, PlantregError

SUBCOMMANDS = ("demo", "register", "calibrate", "fit_rig", "recording", "batch")  # modules NAME_cmd


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
        if message == msg and fraction - frac < 0.05 and now - t < 2.0:
            return
        self._last = (message, fraction, now)
        print(f"[{100 * fraction:3.0f}%] {message}", file=sys.stderr, flush=True)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="plantreg", description="Multimodal 3D image registration for plant phenotyping")
    p.add_argument("--version", action="version", version=f"plantreg {__version__}")
    sub = p.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name in SUBCOMMANDS:
        mod = importlib.import_module(f".{name}_cmd", __name__)
        mod.add_parser(sub)
    return p


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    # the words of this command line, for provenance (sys.argv is someone else's when called in-process)
    args.argv = list(sys.argv[1:] if argv is None else argv)
    try:
        return int(args.run(args) or 0)
    except Cancelled:
        print("plantreg: cancelled", file=sys.stderr)
        return 130
    except KeyboardInterrupt:
        print("plantreg: interrupted", file=sys.stderr)
        return 130
    except PlantregError as e:
        print(f"plantreg: error: {e}", file=sys.stderr)
        return 1
    except MemoryError:
        print("plantreg: error: out of memory", file=sys.stderr)
        return 1
    except OSError as e:  # disk full, no permission, a file where a folder should be: name it, no traceback
        where = f"{e.filename}: " if e.filename else ""
        print(f"plantreg: error: {where}{e.strerror or e}", file=sys.stderr)
        return 1


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
