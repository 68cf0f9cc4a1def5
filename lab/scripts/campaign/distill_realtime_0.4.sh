#!/usr/bin/env bash
# Distil the real-time SALAD student (issue on SALAD 0.4) from a teacher pipeline folder by latent consistency
# distillation (lab/scripts/salad/distill_realtime.py), export its weight folder, and time it against the teacher.
#
# Usage: bash lab/scripts/campaign/distill_realtime_0.4.sh [--dry-run] [OUT]   (default OUT: ~/salad-runs/realtime-0.4)
#   TEACHER=DIR   teacher pipeline folder (default: ~/salad-runs/salad-0.4/weights; the shipped 0.3 is
#                 salad_core/weights/salad, with its corpus 2.4)
#   CORPUS=DIR    the corpus the teacher was trained on (required: corpus 2.8 for 0.4)
#   RESUME=1      continue an interrupted run (Ctrl-C writes a checkpoint every 250 steps)
#   THREADS=N     torch threads (default 2: run it alone; 1 if anything else runs)
#   STEPS=N       optimiser steps in total (default 8000)
# Cost, measured (2026-12-08, 0.3 teacher, one thread beside a KeyMotion run): 700 latent-run frames/s whatever the
# batch, i.e. 11 s a step at batch 64 x 196 frames (20,000 steps would take about 60 hours) and 2.7 s at batch 16;
# hence batch 16 and 8,000 steps here (about 6 hours on one thread beside another run, less alone on 2). Judge the
# checkpoints with Table 1 (evaluate_candidate.sh on OUT/weights) before running longer.
set -euo pipefail
cd "$(dirname "$0")/../../.."
DRY=0
if [ "${1:-}" = "--dry-run" ]; then DRY=1; shift; fi
OUT=${1:-$HOME/salad-runs/realtime-0.4}
PY=${PYTHON:-.venv/bin/python}
TEACHER=${TEACHER:-$HOME/salad-runs/salad-0.4/weights}
RESUME=${RESUME:+--resume}
THREADS=${THREADS:-2}
STEPS=${STEPS:-8000}
if [ -z "${CORPUS:-}" ]; then echo "CORPUS=DIR is required: the corpus the teacher was trained on" >&2; exit 2; fi
if [ "$DRY" = 0 ] && [ ! -f "$TEACHER/pipeline.json" ]; then
  echo "teacher $TEACHER has no pipeline.json: train it first (lab/scripts/campaign/train_salad_0.4.sh) or set TEACHER" >&2
  exit 2
fi
run() { if [ "$DRY" = 1 ]; then printf "%q " "$@"; echo; else echo "+ $*"; "$@"; fi; }
run "$PY" lab/scripts/salad/distill_realtime.py --teacher "$TEACHER" --data "$CORPUS" --out "$OUT/run" \
    --steps "$STEPS" --batch-size 16 --ckpt-every 250 --val-every 500 --threads "$THREADS" $RESUME
run "$PY" lab/scripts/salad/distill_realtime.py --teacher "$TEACHER" --out "$OUT/run" --export "$OUT/weights"
TIME=("$PY" lab/scripts/salad/distill_realtime.py --teacher "$TEACHER" --student "$OUT/weights" --time --threads 2)
if [ "$DRY" = 1 ]; then run "${TIME[@]}"; else run "${TIME[@]}" | tee "$OUT/timing.jsonl"; fi
