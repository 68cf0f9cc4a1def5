#!/usr/bin/env bash
# Train the SALAD 0.4 candidate (issue on SALAD 0.4): SALAD 0.3's denoiser recipe on corpus 2.8 (corpus 2.7 plus the
# captioned general-motion clips) over the shipped general-motion VAE's latents, then assemble a pipeline folder.
#
# Usage: bash lab/scripts/campaign/train_salad_0.4.sh [--dry-run] [OUT]     (default OUT: ~/salad-runs/salad-0.4)
#   RESUME=1      continue an interrupted denoiser run (Ctrl-C writes a checkpoint)
#   CORPUS=DIR    a corpus 2.8 built before (default: built into OUT/corpus28)
# Stages: corpus 2.8 (`salad corpus build --with-general --size default --seed 0`), the denoiser
# (lab/configs/salad-0.4_denoiser.json, 10,000 steps, about 5.5 hours on 2 threads), the fp16 pipeline folder
# OUT/weights with SALAD 0.3's default guidance (w 4.5, fit recovery) until a guidance sweep chooses 0.4's.
# The evaluator for its Table 1 is trained on the same corpus: CORPUS=DIR bash scripts/reproduce_evaluator.sh OUT2.
set -euo pipefail
cd "$(dirname "$0")/../../.."
DRY=0
if [ "${1:-}" = "--dry-run" ]; then DRY=1; shift; fi
OUT=${1:-$HOME/salad-runs/salad-0.4}
PY=${PYTHON:-.venv/bin/python}
RESUME=${RESUME:+--resume}
run() { if [ "$DRY" = 1 ]; then printf "%q " "$@"; echo; else echo "+ $*"; "$@"; fi; }
[ "$DRY" = 1 ] || mkdir -p "$OUT"
if [ -z "${CORPUS:-}" ]; then
  CORPUS=$OUT/corpus28
  [ -f "$CORPUS/corpus.json" ] || run "$PY" -m salad_core.cli corpus build --out "$CORPUS" --size default --seed 0 \
      --with-general
fi
run "$PY" -m salad_core.train denoiser --data "$CORPUS" --out "$OUT/denoiser" --vae salad_core/weights/general_vae/vae \
    --config lab/configs/salad-0.4_denoiser.json --no-progress $RESUME
run "$PY" scripts/assemble_weights.py --vae salad_core/weights/general_vae/vae --denoiser "$OUT/denoiser" \
    --out "$OUT/weights"
run "$PY" -c 'import json, sys; p = sys.argv[1] + "/pipeline.json"; d = json.load(open(p)); d["guidance"] = {"scale": 4.5, "rescale": 0.0, "interval": None}; d["recovery"] = "fit"; open(p, "w").write(json.dumps(d, indent=2) + "\n")' "$OUT/weights"
