#!/usr/bin/env bash
# Evaluate a candidate SALAD pipeline against the shipped one, stage by stage, resumable: the measurements that
# decide whether a retrained model ships (issue 20's targets; lab/docs/campaign.md).
#
# Usage: bash lab/scripts/campaign/evaluate_candidate.sh OUT_DIR [STAGE...]
#   OUT_DIR   results folder, outside the repository (e.g. ~/salad-runs/v3/measure/v3)
#   STAGE     any of: assemble physics t2m t2m_shipped sweep editing (default: all, in that order); t2m_shipped
#             measures the shipped pipeline with the same protocol, data and evaluator, for the comparison
# Environment:
#   DATA       procedural corpus the models trained on (its test split and references; required)
#   WEIGHTS    the candidate pipeline folder (default OUT_DIR/weights, written by the assemble stage)
#   VAE, DENOISER  for the assemble stage: a denoiser run folder and its VAE (run or exported folder; default the
#              one the denoiser run recorded; another VAE is refused)
#   EVALUATOR  T2M evaluator folder trained on DATA (default: the shipped one)
#   SCALES     guidance weights of the sweep (default 1,2,3,4.5,6,7.5); RESCALES (default 0,0.7)
#   PHYSICS_ARGS  extra arguments of the physics stage (default none: 41 prompts x 3 seeds, 50 steps)
#   T2M_ARGS   the T2M protocol's budget (default "--replications 5 --max-samples 256 --no-mm": the full protocol,
#              20 replications of the whole test split with MultiModality, takes days on a CPU)
#   SWEEP_SEEDS, SWEEP_PROMPTS, SWEEP_REPLICATIONS, SWEEP_SAMPLES  the sweep's budget (default 2, all, 3, 128);
#              the sweep keeps each finished candidate (OUT_DIR/sweep/candidates) and continues where it stopped
#   THREADS    torch threads (default 2); PYTHON the python to use
# Each finished stage leaves OUT_DIR/<stage>.done; running again skips it (delete the marker to redo one).
# Everything is measured on the procedural corpus and the benchmark prompts; the real evaluation clips are
# only reported on (never tuned on).
set -euo pipefail
cd "$(dirname "$0")/../../.."   # the repository
OUT=${1:?usage: evaluate_candidate.sh OUT_DIR [STAGE...]}
shift || true
STAGES=${*:-assemble physics t2m t2m_shipped sweep editing}
read -r -a PHYS <<< "${PHYSICS_ARGS:-}"
read -r -a T2M <<< "${T2M_ARGS:---replications 5 --max-samples 256 --no-mm}"
PY=${PYTHON:-.venv/bin/python}
: "${DATA:?set DATA to the procedural corpus the candidate trained on}"
WEIGHTS=${WEIGHTS:-$OUT/weights}
THREADS=${THREADS:-2}
EVAL_ARGS=(--data "$DATA" --threads "$THREADS")
[ -n "${EVALUATOR:-}" ] && EVAL_ARGS+=(--evaluator "$EVALUATOR")
export SALAD_OMP_WAIT=${SALAD_OMP_WAIT:-passive}
mkdir -p "$OUT"
source lab/scripts/_stages.sh   # has STAGE, stage NAME CMD...

if has assemble; then
  if [ -f "$WEIGHTS/pipeline.json" ] && [ -z "${DENOISER:-}" ]; then
    echo "[assemble] $WEIGHTS exists and no DENOISER given: skipped"
  else
    : "${DENOISER:?set DENOISER to the denoiser run folder (or WEIGHTS to an assembled pipeline)}"
    stage assemble "$PY" scripts/assemble_weights.py ${VAE:+--vae "$VAE"} \
        --denoiser "$DENOISER" --out "$WEIGHTS"
  fi
fi
has physics && stage physics "$PY" -m salad_core.cli eval --physics "${EVAL_ARGS[@]}" ${PHYSICS_ARGS:+"${PHYS[@]}"} --weights "$WEIGHTS" \
    --out "$OUT/physics"
has t2m && stage t2m "$PY" -m salad_core.cli eval "${EVAL_ARGS[@]}" "${T2M[@]}" --weights "$WEIGHTS" \
    --name candidate --out "$OUT/t2m"
has t2m_shipped && stage t2m_shipped "$PY" -m salad_core.cli eval "${EVAL_ARGS[@]}" "${T2M[@]}" --name shipped \
    --out "$OUT/t2m_shipped"
has sweep && stage sweep "$PY" -m salad_core.cli eval --guidance-sweep "${EVAL_ARGS[@]}" --weights "$WEIGHTS" \
    --scales "${SCALES:-1,2,3,4.5,6,7.5}" --rescales "${RESCALES:-0,0.7}" --seeds "${SWEEP_SEEDS:-2}" \
    ${SWEEP_PROMPTS:+--prompts "$SWEEP_PROMPTS"} --replications "${SWEEP_REPLICATIONS:-3}" \
    --max-samples "${SWEEP_SAMPLES:-128}" --no-mm --out "$OUT/sweep"
has editing && stage editing "$PY" lab/scripts/editing/measure_editing.py --data "$DATA" --weights "$WEIGHTS" \
    --threads "$THREADS" --json "$OUT/editing.json"
echo "results in $OUT"
