#!/usr/bin/env bash
# Issue 24: how far does the training seed alone move an ablation row? Study denoiser variants trained again from
# scratch with another train.seed (the study's recipe otherwise): lab/scripts/ablations/probe_denoisers.sh with the change
# train.seed=SEED (records <variant>_s<SEED>, continued runs in OUT/decay_s<SEED>).
# Usage: bash lab/scripts/ablations/probe_training_seed.sh OUT SEED VARIANT [VARIANT ...]   (e.g. OUT 2026 full no_st x0)
# Run it again to resume.
set -euo pipefail
OUT=${1:?usage: bash lab/scripts/ablations/probe_training_seed.sh OUT SEED VARIANT [VARIANT ...]}
SEED=${2:?give a training seed}
shift 2
exec bash "$(dirname "$0")/probe_denoisers.sh" "$OUT" "s$SEED" "training seed $SEED" "train.seed=$SEED" "$@"
