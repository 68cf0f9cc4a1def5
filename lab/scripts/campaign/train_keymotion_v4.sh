#!/usr/bin/env bash
# Train the KeyMotion v4 candidate: absolute keyframe timing (lab/configs/keymotion-v4-absolute.json), i.e. a new
# keyframe VAE whose positions are frame indices and a new side-canonical PST without the middle skip pair on its
# latents, assembled with KeyMotion 0.2's MMAE (trained on motion alone, independent of both).
#
# Usage: bash lab/scripts/campaign/train_keymotion_v4.sh [--dry-run] [OUT]     (default OUT: ~/salad-runs/km_v4)
#   RESUME=1      continue interrupted stages (Ctrl-C writes a checkpoint); a finished stage is skipped
#   CORPUS=DIR    corpus 2.7 built before (default: built into OUT/corpus27)
#   THREADS=N     torch threads (default 1: on 2 threads with another process beside it the run crawls, 1.0 against
#                 5.0 steps/s; alone, 1 thread is as fast as 2: lab/docs/keymotion.md)
# Stages: keyframe VAE (30,000 steps, about 1.5 hours on 1 thread), PST (60,000 steps, 3.5-6 hours on 1 thread), the
# pipeline folder OUT/pipe. Why: lab/docs/keymotion.md, "A one-action prompt asked for longer is slowed down".
set -euo pipefail
cd "$(dirname "$0")/../../.."
DRY=0
if [ "${1:-}" = "--dry-run" ]; then DRY=1; shift; fi
OUT=${1:-$HOME/salad-runs/km_v4}
PY=${PYTHON:-.venv/bin/python}
RESUME=${RESUME:+--resume}
THREADS=${THREADS:-1}
RECIPE=lab/configs/keymotion-v4-absolute.json
run() { if [ "$DRY" = 1 ]; then printf "%q " "$@"; echo; else echo "+ $*"; "$@"; fi; }
done_stage() { [ -f "$1/train_state.json" ] && "$PY" -c 'import json, sys; d = json.load(open(sys.argv[1] + "/train_state.json")); sys.exit(0 if d["step"] >= int(sys.argv[2]) else 1)' "$1" "$2"; }
[ "$DRY" = 1 ] || mkdir -p "$OUT"
if [ -z "${CORPUS:-}" ]; then
  CORPUS=$OUT/corpus27
  [ -f "$CORPUS/corpus.json" ] || run "$PY" -m salad_core.cli corpus build --out "$CORPUS" --size default --seed 0
fi
if [ "$DRY" = 1 ] || ! done_stage "$OUT/kf_vae" 30000; then
  run "$PY" lab/scripts/keymotion/finetune_keymotion.py --stage kf_vae --scratch --recipe "$RECIPE" --data "$CORPUS" \
      --out "$OUT/kf_vae" --steps 30000 --threads "$THREADS" $RESUME
fi
run "$PY" lab/scripts/keymotion/finetune_keymotion.py --stage pst --scratch --side-canonical --no-middle-skip \
    --kf-vae "$OUT/kf_vae" --recipe "$RECIPE" --data "$CORPUS" --out "$OUT/pst" --steps 60000 --threads "$THREADS" \
    --export "$OUT/pipe" $RESUME
