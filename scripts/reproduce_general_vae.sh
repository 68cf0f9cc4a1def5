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
source scripts/_reproduce_common.sh runs/reproduce/general_vae "$@"
corpus_data
general_data
run "$PY" -m salad_core.train vae --data "$CORPUS" --general "$GENERAL" --out "$OUT/vae" \
    --config configs/general-vae.json --no-progress $RESUME
# the VAE folder, float32 (a denoiser trained on it sees exactly the run's latents)
run "$PY" -c 'import sys; from salad_core.train.assemble import export_vae; print(export_vae(sys.argv[1], sys.argv[2], dtype=None))' \
    "$OUT/vae" "$OUT/weights"
