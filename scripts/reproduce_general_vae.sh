#!/usr/bin/env bash
# Reproduce the general motion VAE (salad_core/weights/general_vae) from its config.
#
# Usage: bash scripts/reproduce_general_vae.sh [--dry-run] [OUT]   (default OUT: runs/reproduce/general_vae)
#   --dry-run   print the commands and run nothing
#   RESUME=1    continue an interrupted run (Ctrl-C writes a checkpoint)
#   PYTHON      the python to use (default .venv/bin/python)
#
# Stages: the data (procedural corpus, size default, seed 0; 4,000 general motions, seed 0), the VAE
# (configs/general-vae.json, 12,000 steps, about 90 minutes on a 2-core CPU), the float32 VAE folder
# OUT/weights. Everything is written under OUT; an OUT inside salad_core/weights is refused.
# CORPUS=DIR / GENERAL=DIR use data built before, as they are. The shipped VAE saw corpus generator 2.4 and general-motion
# generator 1.0 (commit 197e7fc): scripts/reproduce_salad.sh's header says how to build that data.
set -euo pipefail
cd "$(dirname "$0")/.."
DRY=0
if [ "${1:-}" = "--dry-run" ]; then DRY=1; shift; fi
OUT=${1:-runs/reproduce/general_vae}
PY=${PYTHON:-.venv/bin/python}
RESUME=${RESUME:+--resume}
case "$(realpath -m "$OUT")/" in "$(realpath -m salad_core/weights)"/*)
  echo "refusing to write into the shipped weights ($OUT): give a folder outside salad_core/weights" >&2; exit 2;; esac
run() { if [ "$DRY" = 1 ]; then printf "%q " "$@"; echo; else echo "+ $*"; "$@"; fi; }
[ "$DRY" = 1 ] || mkdir -p "$OUT"
if [ -z "${CORPUS:-}" ]; then    # a given CORPUS is used as it is
  CORPUS=$OUT/corpus
  [ -f "$CORPUS/corpus.json" ] || run "$PY" -m salad_core.cli corpus build --out "$CORPUS" --size default --seed 0
fi
if [ -z "${GENERAL:-}" ]; then   # a given GENERAL is used as it is
  GENERAL=$OUT/general
  [ -f "$GENERAL/general.json" ] || run "$PY" scripts/build_general_motion.py --out "$GENERAL" --n 4000 --seed 0
fi
run "$PY" -m salad_core.train vae --data "$CORPUS" --general "$GENERAL" --out "$OUT/vae" \
    --config configs/general-vae.json --no-progress $RESUME
# the VAE folder, float32 (a denoiser trained on it sees exactly the run's latents)
run "$PY" -c 'import sys; from salad_core.train.assemble import export_vae; print(export_vae(sys.argv[1], sys.argv[2], dtype=None))' \
    "$OUT/vae" "$OUT/weights"
