#!/usr/bin/env bash
# One-command set-up on a fresh machine: creates .venv and installs salad with its notebook and
# test extras from the pinned requirements (CPU torch, JupyterLab, Playwright), plus the system
# packages below when root. Usage: bash scripts/setup.sh
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}
if [ ! -x .venv/bin/python ]; then
  "$PY" -m venv .venv
fi
.venv/bin/python -m pip install --quiet --upgrade pip
.venv/bin/python -m pip install --quiet -r requirements.txt
.venv/bin/python -m pip install --quiet --no-deps -e .
# System packages, installed with apt only when missing and we are root (a no-op otherwise):
# - the Mesa libraries: off-screen rendering uses the VTK wheel's EGL path;
# - Debian's Chromium: tests/test_browser.py drives it through Playwright (never `playwright
#   install`, which would download a browser build of its own); without it that test skips.
# - Debian's Blender: tests/test_bvh_blender.py reads the BVH files salad writes with Blender's own
#   importer (measured: 65 s, 178 packages, 74 MB download); without it that test skips.
APT_UPDATED=0
apt_install() {  # apt_install WHAT PACKAGE...: quiet; warn and carry on when it fails
  local what=$1; shift
  if [ "$(id -u)" != "0" ] || ! command -v apt-get >/dev/null 2>&1; then
    echo "warning: $what missing and not root (or no apt-get): install $* yourself" >&2
    return 0
  fi
  if [ "$APT_UPDATED" = "0" ]; then
    apt-get update -qq >/dev/null 2>&1 || true
    APT_UPDATED=1
  fi
  DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "$@" >/dev/null 2>&1 \
    || echo "warning: could not install $what ($*)" >&2
}
# (grep reads all of ldconfig's output: grep -q could end the pipe early and pipefail would see SIGPIPE)
if ! ldconfig -p | grep 'libEGL.so.1' >/dev/null || ! ldconfig -p | grep 'libOSMesa' >/dev/null; then
  apt_install "the Mesa libraries (renders fall back to the 2D rasteriser)" --no-install-recommends \
    libegl1 libgl1 libgl1-mesa-dri libgbm1 libx11-6 libxcursor1 libosmesa6
fi
if [ ! -x /usr/bin/chromium ]; then
  apt_install "Chromium (tests/test_browser.py will skip)" chromium
fi
if ! command -v blender >/dev/null 2>&1; then
  apt_install "Blender (tests/test_bvh_blender.py will skip)" blender
fi
.venv/bin/python -c "import salad_core, torch; print('salad', salad_core.__version__, '| torch', torch.__version__)"
echo "Set-up done. Activate with: source .venv/bin/activate"
