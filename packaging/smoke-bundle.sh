#!/usr/bin/env bash
# Smoke test of the frozen bundle, headless, from a scratch folder and with no Python environment
# of ours visible (PYTHONPATH, PYTHONHOME, VIRTUAL_ENV unset; the bundle must carry everything):
#   bash packaging/smoke-bundle.sh [BUNDLE_DIR]     (default dist/plantreg; run by packaging/bundle.sh)
# Runs `plantreg --version`, `plantreg demo`, `plantreg register` on the demo and checks its
# outputs, `plantreg-gui --demo --screenshot` under xvfb-run (else Qt's offscreen platform) and
# `plantreg-gui --calibrate-demo --page 3 --screenshot` (the wizard's worker process) and checks
# the screenshots are not blank and the wizard run printed no error, checks the packaged icon and desktop entry
# (`plantreg-gui --install-desktop` into a scratch XDG_DATA_HOME, validated, then uninstalled),
# and prints the bundle's size and start-up time: the wall time of `plantreg-gui --screenshot`
# of the empty window (start, splash, window, 0.5 s idle, grab, exit), and with BASELINE_GUI set
# (a command running the same program from a venv, as packaging/bundle.sh does) its ratio to that.
# PY: a Python with numpy, Pillow and tifffile to read the screenshots and a registered TIFF (default .venv/bin/python, else python3).
# Exit 0: every check passed.
set -euo pipefail
ROOT=$(cd "$(dirname "$0")/.." && pwd)
B=$(cd "${1:-$ROOT/dist/plantreg}" && pwd)
PY=${PY:-$ROOT/.venv/bin/python}
[ -x "$PY" ] || PY=python3
[ -x "$B/plantreg" ] && [ -x "$B/plantreg-gui" ] || { echo "smoke-bundle: no plantreg/plantreg-gui in $B" >&2; exit 1; }
W=$(mktemp -d -t plantreg-smoke.XXXXXX)
cd "$W"
unset PYTHONPATH PYTHONHOME VIRTUAL_ENV
fail() { echo "smoke-bundle: FAILED: $*" >&2; exit 1; }
. "$ROOT/packaging/checks.sh"
secs() { "$PY" -c 'import sys, time; print(f"{time.time() - float(sys.argv[1]):.1f}")' "$1"; }
now() { "$PY" -c 'import time; print(time.time())'; }
T0=$(now)

echo "bundle: $B, $(du -sm "$B" | cut -f1) MiB, $(find "$B" -type f | wc -l) files"
"$B/plantreg" --version
[ "$("$B/plantreg-gui" --version)" = "$("$B/plantreg" --version)" ] || fail "plantreg-gui --version differs"

t=$(now)
"$B/plantreg" demo demo
"$B/plantreg" register --rig demo/rig.json --recording demo/recording --target ir --out demo/out
for f in summary.json registered/thermal.tif registered/hyperspectral.tif pointcloud.ply mosaic.png; do
  [ -s "demo/out/$f" ] || fail "plantreg register wrote no $f"
done
# the registered TIFFs are deflate with a floating-point predictor (imagecodecs' codecs in the bundle)
"$PY" - demo/out/registered/thermal.tif <<'EOF' || fail "registered/thermal.tif"
import sys
import numpy as np
import tifffile
a = tifffile.imread(sys.argv[1])
v = a[np.isfinite(a)]
print(f"{sys.argv[1]}: {a.shape} {a.dtype}, {v.size} registered pixels, median {np.median(v):.2f} deg C")
assert v.size > 0.05 * a.size and 15 < np.median(v) < 35, "the registered thermal image is not a leaf's temperature"
EOF
echo "plantreg demo + register: $(secs "$t") s"

t=$(now)
headless "$B/plantreg-gui" --screenshot empty.png --timeout 120 >/dev/null
START=$(secs "$t")
echo "start-up (plantreg-gui --screenshot of the empty window, start to exit): $START s"
if [ -n "${BASELINE_GUI:-}" ]; then
  t=$(now)
  headless $BASELINE_GUI --screenshot empty-venv.png --timeout 120 >/dev/null
  BASE=$(secs "$t")
  echo "same from the venv ($BASELINE_GUI): $BASE s; bundle / venv = $("$PY" -c "print(f'{$START / $BASE:.2f}')")"
fi

t=$(now)
headless "$B/plantreg-gui" --demo --screenshot demo.png --timeout 600
echo "plantreg-gui --demo --screenshot: $(secs "$t") s"
check_screenshot "$PY" demo.png || fail "the screenshot looks blank"

# the wizard's calculations run in a spawned worker process: in a frozen app that process is the
# bundle's own executable again (multiprocessing.freeze_support)
t=$(now)
headless "$B/plantreg-gui" --calibrate-demo --page 3 --screenshot wizard.png --timeout 900 2>wizard.err \
  || { cat wizard.err >&2; fail "plantreg-gui --calibrate-demo --page 3"; }
echo "plantreg-gui --calibrate-demo --page 3 --screenshot: $(secs "$t") s"
check_screenshot "$PY" wizard.png || fail "the wizard's screenshot looks blank"
! grep -E "Traceback|Exception ignored" wizard.err || fail "the wizard run printed errors (above)"

check_desktop "$B/plantreg-gui" "$W" || fail "desktop entry"

echo "smoke test passed in $(secs "$T0") s (screenshots in $W)"
