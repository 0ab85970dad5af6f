#!/usr/bin/env bash
# Install plantreg as a user would and check the installed programs work:
#   bash packaging/check-wheel.sh [WORKDIR]
# Builds the wheel from this checkout (from a copy: setuptools writes build/ beside the sources),
# installs it into a fresh venv (no --system-site-packages: only what the wheel declares; pip's
# download cache is reused), then from a folder outside the checkout runs `plantreg --version`,
# `plantreg demo`, `plantreg register`, `plantreg-gui --demo --screenshot` (under xvfb-run, else
# Qt's offscreen platform) and checks the screenshot is not blank, and that the installed package
# carries its icon and desktop entry: `plantreg-gui --install-desktop` into a scratch
# XDG_DATA_HOME, the entry validated (desktop-file-validate when installed) and pointing at the
# venv's plantreg-gui, then `--uninstall-desktop` leaves nothing behind.
# Needs the package registry (or a filled pip cache) and the system libraries of
# packaging/system-deps.sh. WORKDIR (default: a new temporary folder) is kept for inspection.
# Exit 0: every check passed; the last line gives the time taken.
set -euo pipefail
ROOT=$(cd "$(dirname "$0")/.." && pwd)
PY=${PYTHON:-python3}
WORK=${1:-$(mktemp -d -t plantreg-wheel.XXXXXX)}
mkdir -p "$WORK"
WORK=$(cd "$WORK" && pwd)
T0=$(date +%s)
step() { echo "== [$(( $(date +%s) - T0 )) s] $*"; }
fail() { echo "check-wheel: FAILED: $*" >&2; exit 1; }
. "$ROOT/packaging/checks.sh"

step "copy the sources to $WORK/src"
rm -rf "$WORK/src" "$WORK/dist" "$WORK/venv" "$WORK/run" "$WORK/xdg"
mkdir -p "$WORK/src" "$WORK/run"
cp -r "$ROOT/pyproject.toml" "$ROOT/README.md" "$ROOT/LICENSE" "$ROOT/plantreg_gui" "$WORK/src/"
find "$WORK/src" -name __pycache__ -prune -exec rm -rf {} +

step "fresh venv"
"$PY" -m venv "$WORK/venv"
VPY="$WORK/venv/bin/python"
"$VPY" -m pip install -q --upgrade pip

step "build the wheel (isolated build: the setuptools pyproject.toml asks for)"
"$VPY" -m pip wheel -q --no-deps -w "$WORK/dist" "$WORK/src"
WHEEL=$(ls "$WORK"/dist/plantreg-*.whl)
echo "wheel: $WHEEL ($(du -k "$WHEEL" | cut -f1) KiB)"

step "install the wheel and its dependencies"
"$VPY" -m pip install -q "$WHEEL"
echo "venv: $(du -sm "$WORK/venv" | cut -f1) MiB"

cd "$WORK/run"  # outside the checkout: nothing can be imported from the sources
export PATH="$WORK/venv/bin:$PATH"
step "the installed package"
"$VPY" - "$WORK/venv" <<'EOF'
import sys
from pathlib import Path
import plantreg_gui
from plantreg_gui import resources
venv = Path(sys.argv[1]).resolve()
where = Path(plantreg_gui.__file__).resolve()
assert venv in where.parents, f"plantreg_gui imported from {where}, not from the venv"
for name in resources.FILES:
    data = resources.read_bytes(name)
    assert data, f"packaged {name} is empty"
    print(f"packaged {name}: {len(data)} bytes at {resources.path(name)}")
EOF
V=$(plantreg --version)
VG=$(plantreg-gui --version)
EXPECT="plantreg $("$VPY" -c 'import plantreg_gui; print(plantreg_gui.__version__)')"
[ "$V" = "$EXPECT" ] && [ "$VG" = "$EXPECT" ] || fail "versions: plantreg '$V', plantreg-gui '$VG', package '$EXPECT'"
echo "$V"

step "plantreg demo + register"
plantreg demo demo
plantreg register --rig demo/rig.json --recording demo/recording --target ir --out demo/out
[ -f demo/out/summary.json ] || fail "register wrote no summary.json"

step "plantreg-gui --demo --screenshot"
headless plantreg-gui --demo --screenshot shot.png --timeout 600
check_screenshot "$VPY" shot.png || fail "the screenshot looks blank"

step "plantreg-gui --install-desktop / --uninstall-desktop"
check_desktop "$WORK/venv/bin/plantreg-gui" "$WORK" || fail "desktop entry"

step "all checks passed in $(( $(date +%s) - T0 )) s (work folder $WORK)"
