#!/usr/bin/env bash
# Issue 24: how far does the training seed alone move an ablation row? Study denoiser variants trained again from
# scratch with another train.seed (the study's recipe otherwise), each scored at the study's 8,000-step stage with its
# protocol (recorded in studies/ablations_v2/probes.json as <variant>_s<SEED>), then continued to 10,000 steps with
# the decay of the continuation probe (x0.2 at 8,000 and 9,000) into OUT/decay_s<SEED>, to be scored paired with the
# study's continued rows (scripts/ablation_continuation_probe.py score --probes; see docs/campaign.md).
# Usage: bash scripts/probe_training_seed.sh OUT SEED VARIANT [VARIANT ...]   (e.g. OUT 2026 full no_st x0)
#   STUDY_WORK  the study's work folder (configs/, stages/vaes@6000/models; default ~/salad-runs/ablations_v3)
#   DATA        its corpus (default ~/salad-runs/v3/corpus)
# Run it again to resume: finished runs and recorded scores are skipped. The first two variants are continued with
# the decay before the later ones train, so the first pair's answer comes first. One torch thread per run.
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=${1:?usage: bash scripts/probe_training_seed.sh OUT SEED VARIANT [VARIANT ...]}
SEED=${2:?give a training seed}
shift 2
[ $# -ge 1 ] || { echo "name at least one study denoiser variant (full, no_st, x0, ...)" >&2; exit 2; }
PY=${PYTHON:-.venv/bin/python}
STUDY_WORK=${STUDY_WORK:-$HOME/salad-runs/ablations_v3}
DATA=${DATA:-$HOME/salad-runs/v3/corpus}
STUDY=studies/ablations_v2
DECAY=$OUT/decay_s$SEED
mkdir -p "$OUT"
vae_of() {   # the frozen VAE the study's variant learned on (its run's config.json records it)
    "$PY" -c 'import json,sys; print(json.load(open(sys.argv[1]))["task"]["vae"])' "$STUDY_WORK/den_$1/config.json"
}
step_of() { "$PY" -c 'import json,sys; print(json.load(open(sys.argv[1]))["meta"]["step"])' "$1/latest.json" 2>/dev/null || echo 0; }
train() {    # RUN CONFIG VAE STEPS: train (or resume) RUN to STEPS
    if [ "$(step_of "$1")" -lt "$4" ]; then
        "$PY" -m salad_core.train denoiser --data "$DATA" --out "$1" --config "$2" --vae "$3" --no-progress --resume \
            >> "$1.log" 2>&1
    fi
}
probe() {    # VARIANT: train from scratch with the seed, score at the stage, record
    local v=$1 run=$OUT/den_$1_s$SEED
    [ -f "$run.json" ] || "$PY" scripts/ablation_denoiser_probe.py config --study-configs "$STUDY_WORK/configs" \
        --variant "$v" --vae "$(vae_of "$v")" --set "train.seed=$SEED" --out "$run.json"
    train "$run" "$run.json" "$(vae_of "$v")" 8000
    if ! grep -q "\"${v}_s$SEED\"" "$STUDY/probes.json"; then
        "$PY" scripts/ablation_denoiser_probe.py score --stage-eval "$STUDY/evaluations/denoisers@8000.json" \
            --run "$run" --vae "$(vae_of "$v")" --name "${v}_s$SEED" --variant "$v" \
            --vae-label "the study's own VAE for this row" --set "train.seed=$SEED" \
            --label "$v, training seed $SEED" --data "$DATA" --out "$STUDY/probes.json" >> "$OUT/seed_scores.txt" 2>&1
    fi
}
decay() {    # VARIANT...: continue to 10,000 steps with the decay
    local specs=() v
    for v in "$@"; do specs+=("${v}_s$SEED=$OUT/den_${v}_s$SEED"); done
    "$PY" scripts/ablation_continuation_probe.py prepare --study-work "$STUDY_WORK" --variants "${specs[@]}" \
        --set train.max_steps=10000 "train.milestones=[7500,8500]" --out-dir "$DECAY"
    for v in "$@"; do train "$DECAY/den_${v}_s$SEED" "$DECAY/den_${v}_s$SEED.json" "$(vae_of "$v")" 10000; done
}
first=("${@:1:2}")
for v in "${first[@]}"; do probe "$v"; done
decay "${first[@]}"
for v in "${@:3}"; do probe "$v"; done
[ $# -le 2 ] || decay "${@:3}"
echo "training-seed probe $SEED: trained ($(date))" >> "$OUT/seed_scores.txt"
