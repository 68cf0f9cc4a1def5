#!/usr/bin/env bash
# Issue 24: study denoiser variants trained again from scratch with one change to the study's recipe (--set keys of
# lab/scripts/ablations/ablation_denoiser_probe.py config), each scored at the study's 8,000-step stage with its protocol (recorded
# in lab/records/ablations_v2/probes.json as <variant>_<TAG>), then continued to 10,000 steps with the decay of the
# continuation probe (x0.2 at 8,000 and 9,000) into OUT/decay_<TAG>, to be scored paired with the study's continued
# rows (lab/scripts/ablations/ablation_continuation_probe.py score --probes; see lab/docs/campaign.md).
# Usage: bash lab/scripts/ablations/probe_denoisers.sh OUT TAG "WHAT, IN WORDS" "KEY=VALUE [KEY=VALUE ...]" VARIANT [VARIANT ...]
#   e.g. bash lab/scripts/ablations/probe_denoisers.sh ~/salad-runs/abl_probe s2026 "training seed 2026" train.seed=2026 full no_st
#   STUDY_WORK  the study's work folder (configs/, den_<variant>/; default ~/salad-runs/ablations_v3)
#   DATA        its corpus (default ~/salad-runs/v3/corpus)
#   STUDY       the kept study whose probes.json records the scores (default lab/records/ablations_v2 of this checkout)
#   STAGES      the study's evaluation files (default salad_core/weights/ablations/evaluations: the shipped study's)
#   RECIPE      the study's recipe (default lab/configs/ablations_v2.json), used only when STUDY_WORK has no configs/
# On a new machine: build the corpus and restore the study first (lab/docs/campaign.md, "Start again on a new machine").
# Each variant learns on the frozen VAE its study row learned on. Run it again to resume: finished runs and recorded
# scores are skipped. The first two variants are continued with the decay before the later ones train, so the first
# pair's answer comes first. One torch thread per run (the trainer's default on this machine).
set -euo pipefail
cd "$(dirname "$0")/../../.."   # the repository
usage='usage: bash lab/scripts/ablations/probe_denoisers.sh OUT TAG "WHAT, IN WORDS" "KEY=VALUE ..." VARIANT [VARIANT ...]'
OUT=${1:?$usage}
TAG=${2:?$usage}
WHAT=${3:?$usage}
read -r -a SETS <<< "${4:?$usage}"
shift 4
[ $# -ge 1 ] || { echo "name at least one study denoiser variant (full, no_st, x0, ...)" >&2; exit 2; }
[ ${#SETS[@]} -ge 1 ] || { echo "give at least one KEY=VALUE change (e.g. train.seed=2026)" >&2; exit 2; }
case $TAG in *[!A-Za-z0-9_-]*) echo "TAG '$TAG': use letters, digits, _ and - (it names runs and configs)" >&2; exit 2;; esac
PY=${PYTHON:-.venv/bin/python}
STUDY_WORK=${STUDY_WORK:-$HOME/salad-runs/ablations_v3}
DATA=${DATA:-$HOME/salad-runs/v3/corpus}
STUDY=${STUDY:-lab/records/ablations_v2}   # where the probe records go (a worktree may point at the main checkout)
DECAY=$OUT/decay_$TAG
mkdir -p "$OUT"
# A study restored on a new machine (lab/scripts/ablations/train_ablations.py into an empty work folder) has no run folders and
# no configs/: write its denoisers' final-stage configs and the VAE each learned on (study_vaes.json) from the recipe.
if [ ! -d "$STUDY_WORK/configs" ]; then
    "$PY" lab/scripts/ablations/ablation_denoiser_probe.py study-configs --recipe "${RECIPE:-lab/configs/ablations_v2.json}" \
        --work "$STUDY_WORK"
fi
vae_of() {   # the frozen VAE the study's variant learned on (its run's config.json records it, else study_vaes.json)
    if [ -f "$STUDY_WORK/den_$1/config.json" ]; then
        "$PY" -c 'import json,sys; print(json.load(open(sys.argv[1]))["task"]["vae"])' "$STUDY_WORK/den_$1/config.json"
    else
        "$PY" -c 'import json,sys; print(json.load(open(sys.argv[1]))[sys.argv[2]])' "$STUDY_WORK/study_vaes.json" "$1"
    fi
}
step_of() { "$PY" -c 'import json,sys; print(json.load(open(sys.argv[1]))["meta"]["step"])' "$1/latest.json" 2>/dev/null || echo 0; }
train() {    # RUN CONFIG VAE STEPS: train (or resume) RUN to STEPS
    if [ "$(step_of "$1")" -lt "$4" ]; then
        "$PY" -m salad_core.train denoiser --data "$DATA" --out "$1" --config "$2" --vae "$3" --no-progress --resume \
            >> "$1.log" 2>&1
    fi
}
probe() {    # VARIANT: train from scratch with the change, score at the stage, record
    local v=$1 run=$OUT/den_$1_$TAG
    [ -f "$run.json" ] || "$PY" lab/scripts/ablations/ablation_denoiser_probe.py config --study-configs "$STUDY_WORK/configs" \
        --variant "$v" --vae "$(vae_of "$v")" --set "${SETS[@]}" --out "$run.json"
    train "$run" "$run.json" "$(vae_of "$v")" 8000
    if ! grep -qF "\"${v}_$TAG\"" "$STUDY/probes.json"; then
        "$PY" lab/scripts/ablations/ablation_denoiser_probe.py score --stage-eval "${STAGES:-salad_core/weights/ablations/evaluations}/denoisers@8000.json" \
            --run "$run" --vae "$(vae_of "$v")" --name "${v}_$TAG" --variant "$v" \
            --vae-label "the study's own VAE for this row" --set "${SETS[@]}" \
            --label "$v, $WHAT" --data "$DATA" --out "$STUDY/probes.json" >> "$OUT/scores_$TAG.txt" 2>&1
    fi
}
decay() {    # VARIANT...: continue to 10,000 steps with the decay
    local specs=() v
    for v in "$@"; do specs+=("${v}_$TAG=$OUT/den_${v}_$TAG"); done
    mkdir -p "$DECAY"
    "$PY" lab/scripts/ablations/ablation_continuation_probe.py prepare --study-work "$STUDY_WORK" --variants "${specs[@]}" \
        --set train.max_steps=10000 "train.milestones=[7500,8500]" --out-dir "$DECAY"
    for v in "$@"; do train "$DECAY/den_${v}_$TAG" "$DECAY/den_${v}_$TAG.json" "$(vae_of "$v")" 10000; done
}
first=("${@:1:2}")
for v in "${first[@]}"; do probe "$v"; done
decay "${first[@]}"
for v in "${@:3}"; do probe "$v"; done
[ $# -le 2 ] || decay "${@:3}"
echo "denoiser probe $TAG ($WHAT): trained ($(date))" >> "$OUT/scores_$TAG.txt"
