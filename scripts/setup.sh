#!/usr/bin/env bash
# One-command set-up on a fresh machine: creates .venv and installs salad with its notebook and
# test extras from the pinned requirements (CPU torch). Usage: bash scripts/setup.sh
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}
if [ ! -x .venv/bin/python ]; then
  "$PY" -m venv .venv
fi
.venv/bin/python -m pip install --quiet --upgrade pip
.venv/bin/python -m pip install --quiet -r requirements.txt
.venv/bin/python -m pip install --quiet --no-deps -e .
# Off-screen rendering uses the VTK wheel's EGL path (Mesa), present on this machine image.
# Where the Mesa libraries are missing and we are root, install them (a no-op when present).
if [ "$(id -u)" = "0" ] && command -v apt-get >/dev/null 2>&1; then
  if ! ldconfig -p | grep -q 'libEGL.so.1' || ! ldconfig -p | grep -q 'libOSMesa'; then
    (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends \
      libegl1 libgl1 libgl1-mesa-dri libgbm1 libx11-6 libxcursor1 libosmesa6) >/dev/null 2>&1 \
      || echo "warning: could not install Mesa libraries; renders fall back to the 2D rasteriser" >&2
  fi
fi
.venv/bin/python -c "import salad_core, torch; print('salad', salad_core.__version__, '| torch', torch.__version__)"
echo "Set-up done. Activate with: source .venv/bin/activate"
