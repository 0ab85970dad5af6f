#!/usr/bin/env bash
# Set up plantreg on a fresh Debian/Ubuntu-like machine and run one job:
#   bash packaging/setup.sh demo   -> install, write the built-in demo to ./demo and register it (./demo/out)
#   bash packaging/setup.sh test   -> install with test tools, run the whole test suite
#   bash packaging/setup.sh bundle -> install with PyInstaller, build the one-folder app dist/plantreg/ and
#                                     smoke-test it (packaging/bundle.sh, packaging/smoke-bundle.sh)
#   bash packaging/setup.sh        -> install only
# Creates a virtual environment at .venv in the project root with `plantreg` and `plantreg-gui`.
set -euo pipefail
cd "$(dirname "$0")/.."
job="${1:-install}"
bash packaging/system-deps.sh
PY="${PYTHON:-python3}"
if [ ! -x .venv/bin/python ]; then
  "$PY" -m venv .venv
fi
.venv/bin/python -m pip install -q --upgrade pip
if [ "$job" = "test" ]; then
  .venv/bin/python -m pip install -q -e ".[test]"
elif [ "$job" = "bundle" ]; then
  .venv/bin/python -m pip install -q -e ".[bundle]"
else
  .venv/bin/python -m pip install -q -e .
fi
case "$job" in
  install) echo "installed: .venv/bin/plantreg and .venv/bin/plantreg-gui" ;;
  demo)
    rm -rf demo
    .venv/bin/plantreg demo demo
    .venv/bin/plantreg register --rig demo/rig.json --recording demo/recording --target ir --out demo/out
    echo "demo registered: see demo/out; view it with: .venv/bin/plantreg-gui --rig demo/rig.json --recording demo/recording --target ir"
    ;;
  test)
    shift || true
    .venv/bin/python -m pytest "$@"
    ;;
  bundle) bash packaging/bundle.sh ;;
  *) echo "usage: bash packaging/setup.sh [install|demo|test|bundle]" >&2; exit 2 ;;
esac
