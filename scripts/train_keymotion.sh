#!/usr/bin/env bash
# Reproduce the shipped KeyMotion weights (salad_core/weights/keymotion/) on the procedural corpus.
# Usage: bash scripts/train_keymotion.sh [WORK_DIR]   (default WORK_DIR: ./runs/keymotion)
#   DATA=DIR       the corpus (default: runs/default/corpus, built with seed 0 if missing, as
#                  scripts/train_default.sh does; the shipped run used the same corpus at /work/data_default)
#   RESUME=1       continue an interrupted run (Ctrl-C writes a checkpoint; finished stages are skipped)
#   KF_VAE_STEPS, PST_STEPS, MMAE_STEPS   steps per stage (defaults: the shipped run)
#   DEST=DIR       where the fp16 pipeline folder is written (default salad_core/weights/keymotion)
# One process, one torch thread (num_threads 1 in the config). Wall time on the 2-core CPU of
# this project (shared with another training): see salad_core/weights/keymotion/MODEL_CARD.md.
set -euo pipefail
cd "$(dirname "$0")/.."
WORK=${1:-runs/keymotion}
PY=${PYTHON:-.venv/bin/python}
DATA=${DATA:-runs/default/corpus}
DEST=${DEST:-salad_core/weights/keymotion}
RESUME=${RESUME:+--resume}
KF_VAE_STEPS=${KF_VAE_STEPS:-3000}
PST_STEPS=${PST_STEPS:-5000}
MMAE_STEPS=${MMAE_STEPS:-1400}
export OMP_NUM_THREADS=1 MKL_NUM_THREADS=1
# 1. the corpus (deterministic: the same seed gives byte-identical files)
[ -f "$DATA/corpus.json" ] || "$PY" -m salad_core.cli corpus build --out "$DATA" --size default --seed 0
# 2. keyframe VAE, PST on its latents, MMAE (MiniLM text features), into $WORK/{kf_vae,pst,mmae}
"$PY" -m salad_core.train keymotion --data "$DATA" --out "$WORK" --config configs/default_keymotion.json \
    --steps-per-stage "$KF_VAE_STEPS" "$PST_STEPS" "$MMAE_STEPS" --no-progress $RESUME
# 3. the pipeline folder: each stage's `best` checkpoint (else `latest`), fp16 storage, plus runs.json
"$PY" -c 'import sys
from salad_core.keymotion.export import export_pipeline
dest = export_pipeline(sys.argv[1], sys.argv[2])
size = sum(p.stat().st_size for p in dest.iterdir() if p.suffix == ".safetensors")
print(f"wrote {dest} ({size / 1e6:.2f} MB of safetensors)")' "$WORK" "$DEST"
