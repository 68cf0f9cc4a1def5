#!/usr/bin/env bash
# Evaluate a trained KeyMotion run, stage by stage, resumable: the measurements that decide whether it replaces
# the shipped KeyMotion (issue 22's targets; docs/keymotion_recipe.md, "After the run, before shipping").
#
# Usage: bash scripts/evaluate_keymotion.sh OUT_DIR [STAGE...]
#   OUT_DIR   results folder, outside the repository (e.g. ~/salad-runs/v3/measure/keymotion)
#   STAGE     any of: export guidance physics infill diversity card (default: all, in that order)
#     export     the run's best checkpoints -> OUT_DIR/weights (fp16, KeyMotionPipeline.save_pretrained)
#     guidance   scripts/keymotion_guidance_bench.py over SETTINGS, with SALAD as the reference -> guidance.json
#     physics    salad eval --physics with --keymotion WEIGHTS (41 prompts x 3 seeds, SALAD beside it) -> physics/
#     infill     scripts/keymotion_infill_ratio.py: MMAE against linear interpolation at 10 % and 25 % -> infill.json
#     diversity  scripts/keymotion_diversity.py (latent statistics, guidance, sampler) -> diversity.json
#     card       scripts/keymotion_card_figures.py --eval (reconstruction, generations, quick T2M) -> card.json
# Environment:
#   DATA      procedural corpus the run trained on (its test split, references; required)
#   RUN       the KeyMotion training root (kf_vae/, pst/, mmae/; required by the export stage)
#   WEIGHTS   the pipeline folder to measure (default OUT_DIR/weights, written by export)
#   SETTINGS  guidance settings of the guidance stage (default "7.5 5 2.5 7.5@0-0.5 5@0-0.5": W, W@LO-HI, W^PHI)
#   THREADS   torch threads of the physics stage (default 2); PYTHON the python to use
# Each finished stage leaves OUT_DIR/<stage>.done; running again skips it (delete the marker to redo one). The
# guidance stage does not choose: store the chosen setting with the weights (keymotion.json "guidance") and redo
# the stages after it. Everything is measured on the procedural corpus and the benchmark prompts, never on the real
# evaluation clips.
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=${1:?usage: evaluate_keymotion.sh OUT_DIR [STAGE...]}
shift || true
STAGES=${*:-export guidance physics infill diversity card}
PY=${PYTHON:-.venv/bin/python}
: "${DATA:?set DATA to the procedural corpus the KeyMotion run trained on}"
WEIGHTS=${WEIGHTS:-$OUT/weights}
THREADS=${THREADS:-2}
read -r -a SET <<< "${SETTINGS:-7.5 5 2.5 7.5@0-0.5 5@0-0.5}"
export SALAD_OMP_WAIT=${SALAD_OMP_WAIT:-passive}
mkdir -p "$OUT"
source scripts/_stages.sh   # has STAGE, stage NAME CMD...

if has export; then
  : "${RUN:?set RUN to the KeyMotion training root (or WEIGHTS to an exported pipeline and leave out export)}"
  stage export "$PY" -c 'import sys, torch
from salad_core.keymotion.pipeline import KeyMotionPipeline
out = KeyMotionPipeline.from_pretrained(sys.argv[1]).save_pretrained(sys.argv[2], dtype=torch.float16)
print(f"exported {sys.argv[1]} -> {out}")' "$RUN" "$WEIGHTS"
fi
has guidance && stage guidance "$PY" scripts/keymotion_guidance_bench.py --weights "$WEIGHTS" --settings "${SET[@]}" \
    --salad --out "$OUT/guidance.json"
has physics && stage physics "$PY" -m salad_core.cli eval --physics --data "$DATA" --threads "$THREADS" \
    --keymotion "$WEIGHTS" --out "$OUT/physics"
has infill && stage infill "$PY" scripts/keymotion_infill_ratio.py --weights "$WEIGHTS" --data "$DATA" --limit 150 \
    --ratios 0.1 0.25 --out "$OUT/infill.json"
has diversity && stage diversity "$PY" scripts/keymotion_diversity.py --weights "$WEIGHTS" --data "$DATA" \
    --out "$OUT/diversity.json"
has card && stage card "$PY" scripts/keymotion_card_figures.py --data "$DATA" --weights "$WEIGHTS" --eval \
    --renders "$OUT/renders" --out "$OUT/card.json"
echo "results in $OUT"
