#!/usr/bin/env bash
# Reproduce the shipped default SALAD weights (salad_core/weights/salad/) on the procedural corpus.
# Usage: bash scripts/train_default.sh [WORK_DIR]   (default WORK_DIR: ./runs/default)
# Each stage can be interrupted (Ctrl-C writes a checkpoint) and continued by re-running with
# RESUME=1. Wall time on a 2-core CPU: see salad_core/weights/salad/MODEL_CARD.md.
set -euo pipefail
cd "$(dirname "$0")/.."
WORK=${1:-runs/default}
PY=${PYTHON:-.venv/bin/python}
RESUME=${RESUME:+--resume}
VAE_STEPS=${VAE_STEPS:-1126}   # the shipped VAE: 1,126 steps, checkpoint `best` (step 1,000)
DEN_STEPS=${DEN_STEPS:-3600}   # the shipped denoiser: 3,600 steps (rate step-decayed at 3,000)
mkdir -p "$WORK"
# 1. the corpus (deterministic: the same seed gives byte-identical files)
[ -f "$WORK/corpus/corpus.json" ] || "$PY" -m salad_core.cli corpus build --out "$WORK/corpus" --size default --seed 0
# 2. the skeleto-temporal VAE
"$PY" -m salad_core.train vae --data "$WORK/corpus" --out "$WORK/vae" --config configs/default_vae.json \
    --steps "$VAE_STEPS" --no-progress $RESUME
# 3. the denoiser on latents of the frozen VAE, MiniLM text features
"$PY" -m salad_core.train denoiser --data "$WORK/corpus" --out "$WORK/denoiser" --vae "$WORK/vae" \
    --config configs/default_denoiser.json --steps "$DEN_STEPS" --no-progress $RESUME
# 4. assemble the pipeline folder (fp16 storage)
"$PY" scripts/assemble_weights.py --vae "$WORK/vae" --denoiser "$WORK/denoiser" --out salad_core/weights/salad
