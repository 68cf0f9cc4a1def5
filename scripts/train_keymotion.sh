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
"$PY" - "$WORK" "$DEST" <<'EOF'
import json
import sys
from pathlib import Path

import torch

from salad_core.io import atomic_write_text
from salad_core.keymotion.pipeline import KeyMotionPipeline
from salad_core.keymotion.train import STAGES

work, dest = Path(sys.argv[1]), Path(sys.argv[2])
pipe = KeyMotionPipeline.from_pretrained(work)
pipe.save_pretrained(dest, dtype=torch.float16)
runs = {}
for stage in STAGES:
    run = work / stage
    stem = "best" if (run / "best.json").is_file() else "latest"
    lines = [json.loads(l) for l in (run / "log.jsonl").read_text().splitlines() if l.strip()]
    train_lines = [l for l in lines if "loss" in l]
    val_lines = [l for l in lines if "val_loss" in l]
    runs[stage] = {"checkpoint": stem, "step": json.loads((run / f"{stem}.json").read_text()).get("meta", {}).get("step"),
                   "config": json.loads((run / "config.json").read_text()),
                   "last_log": train_lines[-1] if train_lines else {}, "last_val": val_lines[-1] if val_lines else {}}
atomic_write_text(dest / "runs.json", json.dumps(runs, indent=2) + "\n")
size = sum(p.stat().st_size for p in dest.iterdir() if p.suffix == ".safetensors")
print(f"wrote {dest} ({size / 1e6:.2f} MB of safetensors)")
EOF
