#!/usr/bin/env bash
# Reproduce SALAD 0.3, the shipped default pipeline (salad_core/weights/salad), from its configs.
#
# Usage: bash scripts/reproduce_salad.sh [--dry-run] [OUT]        (default OUT: runs/reproduce/salad)
#   --dry-run   print the commands and run nothing
#   RESUME=1    continue interrupted training stages (Ctrl-C writes a checkpoint)
#   PYTHON      the python to use (default .venv/bin/python)
#   VAE=DIR     skip the VAE stage and use this VAE (a run of scripts/reproduce_general_vae.sh, or the shipped
#               salad_core/weights/general_vae/vae, which gives the same latents)
#
# Stages: the data (procedural corpus, size default, seed 0; 4,000 general motions, seed 0), the VAE
# (configs/salad-0.3/vae.json, 12,000 steps: the general motion VAE), the denoiser on its normalised latents
# (configs/salad-0.3/denoiser.json, 10,000 steps), the fp16 pipeline folder OUT/weights with the default guidance
# w 4.5 (chosen by `salad eval --guidance-sweep`, salad_core/weights/salad/MODEL_CARD.md). About 5 hours on a
# 2-core CPU. Everything is written under OUT; an OUT inside salad_core/weights is refused, so the shipped
# weights are never overwritten. CORPUS=DIR / GENERAL=DIR use data built before, as they are.
#
# The shipped weights were trained on corpus generator 2.4 and general-motion generator 1.0 (commit 197e7fc);
# this checkout builds newer data. For the shipped data build it from a worktree of that commit:
#   git worktree add ../salad-197e7fc 197e7fc && cd ../salad-197e7fc &&
#   PYTHONPATH=. python -m salad_core.cli corpus build --out DIR/corpus --size default --seed 0 &&
#   PYTHONPATH=. python scripts/build_general_motion.py --out DIR/general --n 4000 --seed 0
# then run this script with CORPUS=DIR/corpus GENERAL=DIR/general.
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/_reproduce_common.sh runs/reproduce/salad "$@"
# 1. data (deterministic: the same commit and seed give byte-identical files)
corpus_data
[ -n "${VAE:-}" ] || general_data     # a given VAE needs no general motions
# 2. the VAE on corpus + general motion
if [ -z "${VAE:-}" ]; then
  run "$PY" -m salad_core.train vae --data "$CORPUS" --general "$GENERAL" --out "$OUT/vae" \
      --config configs/salad-0.3/vae.json --no-progress $RESUME
  VAE=$OUT/vae
fi
# 3. the denoiser on the frozen VAE's latents
run "$PY" -m salad_core.train denoiser --data "$CORPUS" --out "$OUT/denoiser" --vae "$VAE" \
    --config configs/salad-0.3/denoiser.json --no-progress $RESUME
# 4. the pipeline folder (fp16), with the shipped default guidance
run "$PY" scripts/assemble_weights.py --vae "$VAE" --denoiser "$OUT/denoiser" --out "$OUT/weights"
run "$PY" -c 'import json, sys; p = sys.argv[1] + "/pipeline.json"; d = json.load(open(p)); d["guidance"] = {"scale": 4.5, "rescale": 0.0, "interval": None}; d["recovery"] = "fit"; open(p, "w").write(json.dumps(d, indent=2) + "\n")' "$OUT/weights"
