#!/usr/bin/env bash
# Reproduce KeyMotion 0.2, the shipped second generator (salad_core/weights/keymotion), from its config.
#
# Usage: bash scripts/reproduce_keymotion.sh [--dry-run] [OUT]     (default OUT: runs/reproduce/keymotion)
#   --dry-run   print the commands and run nothing
#   RESUME=1    continue an interrupted run (finished stages are skipped)
#   PYTHON      the python to use (default .venv/bin/python)
#
# Stages: the procedural corpus (size default, seed 0), the keyframe VAE, PST and MMAE in one process
# (configs/keymotion-0.2.json: 30,000 / 60,000 / 15,000 steps, about 9 hours on a 2-core CPU), the fp16
# pipeline folder OUT/weights. Everything is written under OUT; an OUT inside salad_core/weights is refused.
# CORPUS=DIR uses a corpus built before, as it is. The shipped weights were trained on corpus generator 2.7 (commit
# 4736db4); this checkout's generator is also 2.7, so the corpus it builds is that one.
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/_reproduce_common.sh runs/reproduce/keymotion "$@"
corpus_data
run "$PY" -m salad_core.train keymotion --data "$CORPUS" --out "$OUT/keymotion" \
    --config configs/keymotion-0.2.json --no-progress $RESUME
# the pipeline folder: each stage's best checkpoint, fp16, with runs.json
run "$PY" -c 'import sys; from salad_core.keymotion.export import export_pipeline; print(export_pipeline(sys.argv[1], sys.argv[2]))' \
    "$OUT/keymotion" "$OUT/weights"
