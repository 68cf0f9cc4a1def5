#!/usr/bin/env bash
# Issue 24: is a Table 3 row the denoiser's size? Study denoiser variants (width 96, 3 layers, ff 384) trained again at
# the shipped SALAD denoiser's size (width 128, ff 512, 5 layers; the study's recipe otherwise):
# lab/scripts/ablations/probe_denoisers.sh with those model keys (records <variant>_w128, continued runs in OUT/decay_w128).
# Usage: bash lab/scripts/ablations/probe_denoiser_size.sh OUT VARIANT [VARIANT ...]   (e.g. OUT no_st full)
# Run it again to resume. "full" at one thread: 0.54 steps/s alone on session 35's machine (0.8 on an earlier one; 0.35
# beside a second run), 0.65-0.74 on two threads (set train.num_threads in OUT/den_full_w128.json); "no_st" about 3.
set -euo pipefail
OUT=${1:?usage: bash lab/scripts/ablations/probe_denoiser_size.sh OUT VARIANT [VARIANT ...]}
shift
exec bash "$(dirname "$0")/probe_denoisers.sh" "$OUT" w128 "at the shipped denoiser's size (width 128, 5 layers)" \
    "model.width=128 model.ff_dim=512 model.layers=5" "$@"
