#!/usr/bin/env bash
# Evaluate a trained KeyMotion run, stage by stage, resumable: the measurements that decide whether it replaces
# the shipped KeyMotion (issue 22's targets; lab/docs/keymotion_recipe.md, "After the run, before shipping").
#
# Usage: bash lab/scripts/keymotion/evaluate_keymotion.sh OUT_DIR [STAGE...]
#   OUT_DIR   results folder, outside the repository (e.g. ~/salad-runs/v3/measure/keymotion)
#   STAGE     any of: export guidance physics infill diversity t2m t2m_shipped card (default: all, in that order), and
#             the stages of KeyMotion v2's ship rule (lab/docs/keymotion.md, last section; not in the default list):
#             physics10 sides stretch
#     export     the run's best checkpoints -> OUT_DIR/weights (fp16, salad_core.keymotion.export: runs.json too;
#                GUIDANCE, e.g. 5 or 7.5@0-0.5, is the default guidance stored in keymotion.json)
#     guidance   lab/scripts/keymotion/keymotion_guidance_bench.py over SETTINGS, with SALAD as the reference -> guidance.json
#     physics    salad eval --physics with --keymotion WEIGHTS (41 prompts x 3 seeds, SALAD beside it) -> physics/
#     infill     lab/scripts/keymotion/keymotion_infill_ratio.py: MMAE against linear interpolation at 10 % and 25 % -> infill.json
#     diversity  lab/scripts/keymotion/keymotion_diversity.py (latent statistics, guidance, sampler) -> diversity.json
#     t2m        salad eval --keymotion WEIGHTS: the T2M protocol SALAD's candidates get (evaluate_candidate.sh's t2m:
#                T2M_ARGS, default 5 replications x 256 samples, no MultiModality, 50 steps, w 7.5) -> t2m/
#     t2m_shipped  the same for the shipped KeyMotion -> t2m_shipped/ (Table 1's rows side by side)
#     card       lab/scripts/keymotion/keymotion_card_figures.py --eval (reconstruction, generations, quick T2M) -> card.json
#     physics10  salad eval --physics --seeds 10 with --keymotion WEIGHTS alone, then keymotion_flight_bootstrap.py
#                (the jump prompts' flight fit with a 95 % interval) -> physics10/, physics10_flight.txt
#     sides      keymotion_side_generation.py: the named-side checks on 6 seeds -> sides.json
#     stretch    keymotion_time_stretch_probe.py with the shipped SALAD: peak speeds at 40 / 120 / 196 frames -> stretch.json
# Environment:
#   DATA      procedural corpus the run trained on (its test split, references; required)
#   RUN       the KeyMotion training root (kf_vae/, pst/, mmae/; required by the export stage)
#   WEIGHTS   the pipeline folder to measure (default OUT_DIR/weights, written by export)
#   GUIDANCE  the export stage's default guidance (W, W@LO-HI or W^PHI; default the pipeline's, 7.5)
#   SETTINGS  guidance settings of the guidance stage (default "7.5 5 2.5 7.5@0-0.5 5@0-0.5": W, W@LO-HI, W^PHI)
#   THREADS   torch threads of the physics and t2m stages (default 2); PYTHON the python to use
#   EVALUATOR the T2M evaluator of the t2m stages (default: the packaged one; use the one trained on DATA)
#   T2M_ARGS  protocol options of the t2m stages (default "--replications 5 --max-samples 256 --no-mm")
# Each finished stage leaves OUT_DIR/<stage>.done; running again skips it (delete the marker to redo one). The
# guidance stage does not choose: store the chosen setting with the weights (keymotion.json "guidance") and redo
# the stages after it. Everything is measured on the procedural corpus and the benchmark prompts, never on the real
# evaluation clips.
set -euo pipefail
cd "$(dirname "$0")/../../.."   # the repository
OUT=${1:?usage: evaluate_keymotion.sh OUT_DIR [STAGE...]}
shift || true
STAGES=${*:-export guidance physics infill diversity t2m t2m_shipped card}
PY=${PYTHON:-.venv/bin/python}
: "${DATA:?set DATA to the procedural corpus the KeyMotion run trained on}"
WEIGHTS=${WEIGHTS:-$OUT/weights}
THREADS=${THREADS:-2}
read -r -a SET <<< "${SETTINGS:-7.5 5 2.5 7.5@0-0.5 5@0-0.5}"
read -r -a T2M <<< "${T2M_ARGS:---replications 5 --max-samples 256 --no-mm}"
EVAL_ARGS=(--data "$DATA" --threads "$THREADS")
[ -n "${EVALUATOR:-}" ] && EVAL_ARGS+=(--evaluator "$EVALUATOR")
export SALAD_OMP_WAIT=${SALAD_OMP_WAIT:-passive}
mkdir -p "$OUT"
source lab/scripts/_stages.sh   # has STAGE, stage NAME CMD...

if has export; then
  : "${RUN:?set RUN to the KeyMotion training root (or WEIGHTS to an exported pipeline and leave out export)}"
  stage export "$PY" -c 'import sys
from salad_core.keymotion.export import export_pipeline
from salad_core.sampling import parse_guidance_setting
guidance = parse_guidance_setting(sys.argv[3]) if sys.argv[3] else None
out = export_pipeline(sys.argv[1], sys.argv[2], guidance=guidance)
desc = guidance.describe() if guidance else "7.5 (the pipeline default)"
print(f"exported {sys.argv[1]} -> {out}, default guidance {desc}")' \
      "$RUN" "$WEIGHTS" "${GUIDANCE:-}"
fi
has guidance && stage guidance "$PY" lab/scripts/keymotion/keymotion_guidance_bench.py --weights "$WEIGHTS" --settings "${SET[@]}" \
    --salad --out "$OUT/guidance.json"
has physics && stage physics "$PY" -m salad_core.cli eval --physics --data "$DATA" --threads "$THREADS" \
    --keymotion "$WEIGHTS" --out "$OUT/physics"
has infill && stage infill "$PY" lab/scripts/keymotion/keymotion_infill_ratio.py --weights "$WEIGHTS" --data "$DATA" --limit 150 \
    --ratios 0.1 0.25 --out "$OUT/infill.json"
has diversity && stage diversity "$PY" lab/scripts/keymotion/keymotion_diversity.py --weights "$WEIGHTS" --data "$DATA" \
    --out "$OUT/diversity.json"
has t2m && stage t2m "$PY" -m salad_core.cli eval "${EVAL_ARGS[@]}" "${T2M[@]}" --keymotion "$WEIGHTS" \
    --name "KeyMotion (candidate)" --out "$OUT/t2m"
has t2m_shipped && stage t2m_shipped "$PY" -m salad_core.cli eval "${EVAL_ARGS[@]}" "${T2M[@]}" --keymotion \
    --name "KeyMotion (shipped)" --out "$OUT/t2m_shipped"
has card && stage card "$PY" lab/scripts/keymotion/keymotion_card_figures.py --data "$DATA" --weights "$WEIGHTS" --eval \
    --renders "$OUT/renders" --out "$OUT/card.json"
has physics10 && stage physics10 bash -c '"$1" -m salad_core.cli eval --physics --seeds 10 --no-salad --data "$2" \
    --threads "$3" --keymotion "$4" --out "$5/physics10" && "$1" lab/scripts/keymotion/keymotion_flight_bootstrap.py \
    "$5/physics10/physics.json" | tee "$5/physics10_flight.txt"' _ "$PY" "$DATA" "$THREADS" "$WEIGHTS" "$OUT"
has sides && stage sides "$PY" lab/scripts/keymotion/keymotion_side_generation.py --weights "$WEIGHTS" --seeds 6 \
    --out "$OUT/sides.json"
has stretch && stage stretch "$PY" lab/scripts/keymotion/keymotion_time_stretch_probe.py --other "candidate=$WEIGHTS" \
    --salad --json "$OUT/stretch.json"
echo "results in $OUT"
