#!/usr/bin/env bash
# Issue 22's wide-latent KeyMotion candidate: the keyframe VAE at the paper's latent width (2 x 256, recipe
# lab/configs/v2_keymotion_wide.json: 30,000 steps, x0.2 at 24,000), then a PST with latent normalisation trained from
# scratch on its latents (60,000 steps, x0.2 at 48,000), exported with the shipped MMAE (corpus 2.7's) to be measured.
# Usage: bash lab/scripts/keymotion/train_keymotion_wide.sh WORK      (each step resumes where it stopped: run it again)
#   DATA=DIR   corpus 2.7, the shipped KeyMotion's (default ~/salad-runs/v4/corpus; on a new machine build it from a
#              worktree of 4736db4: python -m salad_core.cli corpus build --out DIR --size default --seed 0)
# Writes WORK/wide30/kf_vae (the VAE; the 1-step PST and MMAE stages of the keymotion trainer beside it are scratch:
# the trainer has no VAE-only mode), WORK/pst and the pipeline WORK/weights_pst. One torch thread per step, as
# docs/performance.md measured best for KeyMotion. Wall time on this project's CPU beside one other run: the VAE
# about 2 h (2.3-4 steps/s), the PST about 4 h (4.1 steps/s) plus 12 minutes of latent encoding.
set -euo pipefail
cd "$(dirname "$0")/../../.."   # the repository
WORK=${1:?usage: bash lab/scripts/keymotion/train_keymotion_wide.sh WORK}
PY=${PYTHON:-.venv/bin/python}
DATA=${DATA:-$HOME/salad-runs/v4/corpus}
RECIPE=lab/configs/v2_keymotion_wide.json
[ -f "$DATA/corpus.json" ] || { echo "no corpus at $DATA (DATA=...; see the header)" >&2; exit 2; }
resume() { [ -f "$1/train_state.json" ] && echo --resume || true; }
# 1. the keyframe VAE (the trainer's first stage; --steps-per-stage gives the PST and MMAE 1 step each)
if [ ! -f "$WORK/wide30/kf_vae/best.json" ] || [ "$("$PY" -c 'import json,sys; print(json.load(open(sys.argv[1]))["meta"]["step"])' "$WORK/wide30/kf_vae/latest.json")" -lt 30000 ]; then
    "$PY" -m salad_core.train keymotion --data "$DATA" --out "$WORK/wide30" --config "$RECIPE" \
        --steps-per-stage 30000 1 1 --no-progress $(resume "$WORK/wide30/kf_vae")
fi
# 2. the PST on its latents, exported with the shipped keyframe-VAE-free parts (the MMAE) into WORK/weights_pst
"$PY" lab/scripts/keymotion/finetune_keymotion.py --stage pst --latent-norm --scratch --kf-vae "$WORK/wide30/kf_vae" \
    --recipe "$RECIPE" --data "$DATA" --out "$WORK/pst" --steps 60000 --threads 1 --export "$WORK/weights_pst" \
    $(resume "$WORK/pst")
