#!/usr/bin/env bash
# Build the one-folder application dist/plantreg/ (programs `plantreg-gui` and `plantreg`) with
# PyInstaller from packaging/pyinstaller/plantreg.spec, then smoke-test it (packaging/smoke-bundle.sh).
#   bash packaging/bundle.sh          (normally via: bash packaging/setup.sh bundle)
# PY: the Python with plantreg's dependencies and PyInstaller (default .venv/bin/python).
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PY:-.venv/bin/python}
case "$PY" in /*) ;; *) PY="$PWD/$PY" ;; esac  # absolute (the smoke test runs elsewhere), link kept: the venv's
export PY
# start-up is compared with the same program run from the venv (packaging/smoke-bundle.sh)
export BASELINE_GUI=${BASELINE_GUI:-"$PY -m plantreg_gui.gui.app"}
T0=$(date +%s)
"$PY" -m PyInstaller --noconfirm --clean --log-level WARN --distpath dist --workpath build/pyinstaller \
  packaging/pyinstaller/plantreg.spec
echo "bundle built in $(( $(date +%s) - T0 )) s: dist/plantreg, $(du -sm dist/plantreg | cut -f1) MiB"
bash packaging/smoke-bundle.sh dist/plantreg
echo "bundle job done in $(( $(date +%s) - T0 )) s"
