#!/usr/bin/env bash
# Set up markerplace on a fresh Debian/Ubuntu machine:
#   1. the Debian packages the headless renderer needs (Mesa EGL, llvmpipe), when missing;
#   2. a virtual environment at .venv in the repository root;
#   3. the package (editable) with its test dependencies, at the exact versions of
#      constraints.txt (the reference environment of docs/results.md).
# Safe to run again: each step is skipped when already done.
set -euo pipefail
cd "$(dirname "$0")/.."

# libusb/libgl1/libgomp1: loaded by Open3D (ray casting, TSDF fusion) even without a device or screen
# poppler-utils: pdftoppm, which the tests use to rasterize tags.pdf
# chromium/chromium-driver: headless browser of the report.html tests (selenium drives /usr/bin/chromedriver)
DEB_PACKAGES=(libegl1 libegl-mesa0 libgl1-mesa-dri libgles2 libglib2.0-0 libgl1 libusb-1.0-0 libgomp1 poppler-utils
              chromium chromium-driver)
PYTHON=${PYTHON:-python3}
# Debian splits venv/ensurepip out of python3: install it when creating .venv would fail.
if [ ! -x .venv/bin/python ] && ! "$PYTHON" -c "import ensurepip, venv" >/dev/null 2>&1; then
  DEB_PACKAGES+=(python3-venv)
fi
missing=()
for pkg in "${DEB_PACKAGES[@]}"; do
  dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "install ok installed" || missing+=("$pkg")
done
if [ ${#missing[@]} -gt 0 ]; then
  echo "setup: installing Debian packages: ${missing[*]}"
  SUDO=""
  [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq "${missing[@]}"
fi

if [ ! -x .venv/bin/python ]; then
  echo "setup: creating .venv"
  "$PYTHON" -m venv .venv
fi
stamp=.venv/.markerplace-setup
want=$(cat pyproject.toml constraints.txt | sha256sum | cut -d' ' -f1)
if [ ! -f "$stamp" ] || [ "$(cat "$stamp")" != "$want" ]; then
  echo "setup: installing Python dependencies into .venv"
  .venv/bin/python -m pip install -q --upgrade pip
  .venv/bin/python -m pip install -q -e ".[test]" -c constraints.txt
  echo "$want" > "$stamp"
fi
echo "setup: ready (.venv/bin/markerplace)"
