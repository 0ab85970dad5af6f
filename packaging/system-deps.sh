#!/usr/bin/env bash
# System libraries that Open3D and Qt need (and Xvfb + Mesa for headless GUI tests,
# desktop-file-validate for the desktop entry's test).
# As root it installs them with apt-get; otherwise it prints the exact command to run.
set -euo pipefail
PKGS=(
  python3-venv
  libusb-1.0-0 libgomp1
  libgl1 libegl1 libgl1-mesa-dri libglib2.0-0 libfontconfig1 libdbus-1-3 fonts-dejavu-core
  libxkbcommon0 libxkbcommon-x11-0 libxcb-cursor0 libxcb-icccm4 libxcb-image0 libxcb-keysyms1
  libxcb-randr0 libxcb-render-util0 libxcb-shape0 libxcb-xinerama0 libxcb-xkb1 libxcb-xfixes0
  libx11-xcb1 libxrender1 libxi6 libxt6 libsm6 libice6
  xvfb xauth
  desktop-file-utils
)
missing=()
for p in "${PKGS[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -eq 0 ]; then
  echo "system libraries: all present"
  exit 0
fi
if ! command -v apt-get >/dev/null 2>&1; then
  echo "plantreg needs these system libraries (Debian/Ubuntu names): ${missing[*]}" >&2
  echo "Install them with your distribution's package manager, then run this again." >&2
  exit 1
fi
if [ "$(id -u)" -ne 0 ]; then
  echo "plantreg needs system libraries that are not installed. Run:" >&2
  echo "  sudo apt-get update && sudo apt-get install -y ${missing[*]}" >&2
  exit 1
fi
echo "installing system libraries: ${missing[*]}"
export DEBIAN_FRONTEND=noninteractive
apt-get update -qq
apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
