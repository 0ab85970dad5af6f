# Checks shared by packaging/check-wheel.sh and packaging/smoke-bundle.sh (sourced, not run).

# headless CMD...: run a Qt program on a virtual screen (xvfb-run), else Qt's offscreen platform.
if command -v xvfb-run >/dev/null 2>&1; then
  headless() { xvfb-run -a -s "-screen 0 1600x1000x24" "$@"; }
else
  headless() { QT_QPA_PLATFORM=offscreen "$@"; }
fi

# check_screenshot PY PNG: fail unless the PNG shows a real window (a blank or black one has a
# handful of colours; the demo's images and 3D view have thousands). PY needs numpy and Pillow.
check_screenshot() {
  "$1" - "$2" <<'PYEOF'
import sys
import numpy as np
from PIL import Image
a = np.asarray(Image.open(sys.argv[1]).convert("RGB")).astype(np.int16)
colours = len(np.unique(a.reshape(-1, 3) // 8, axis=0))
sd = a.mean(axis=2).std()
print(f"screenshot {sys.argv[1]}: {a.shape[1]}x{a.shape[0]}, {colours} colours (5-bit), grey level sd {sd:.1f}")
if not (a.shape[0] > 400 and a.shape[1] > 600 and colours > 500 and sd > 10):
    sys.exit("the screenshot looks blank")
PYEOF
}

# check_desktop GUI WORKDIR: `GUI --install-desktop` into WORKDIR/xdg writes the icon and a valid
# entry whose Exec is GUI's absolute path; `GUI --uninstall-desktop` leaves no file behind.
check_desktop() {
  local gui=$1 xdg=$2/xdg entry
  entry="$xdg/applications/plantreg-gui.desktop"
  XDG_DATA_HOME="$xdg" "$gui" --install-desktop
  [ -s "$entry" ] && [ -s "$xdg/icons/hicolor/scalable/apps/plantreg.svg" ] \
    || { echo "no desktop entry or icon under $xdg" >&2; return 1; }
  grep -qx "Exec=$gui" "$entry" || { echo "Exec does not name $gui: $(grep ^Exec "$entry")" >&2; return 1; }
  if command -v desktop-file-validate >/dev/null 2>&1; then
    desktop-file-validate "$entry" || { echo "desktop-file-validate rejected $entry" >&2; return 1; }
    echo "desktop-file-validate: ok"
  else
    echo "desktop-file-validate not installed (Debian: desktop-file-utils); entry not validated"
  fi
  XDG_DATA_HOME="$xdg" "$gui" --uninstall-desktop
  [ -z "$(find "$xdg" -type f)" ] || { echo "left behind by --uninstall-desktop: $(find "$xdg" -type f)" >&2; return 1; }
}
