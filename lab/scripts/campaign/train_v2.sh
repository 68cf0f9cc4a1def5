#!/usr/bin/env bash
# The v2 training campaign (issues 20, 21 and 22): corpus 2.0, a general motion autoencoder trained on the
# corpus plus uncaptioned general motion, then the denoiser on its latent space, then KeyMotion.
#
# Usage: bash lab/scripts/campaign/train_v2.sh [WORK_DIR] [STAGE...]
#   WORK_DIR   run folder, outside the repository (default: ~/salad-runs/v2)
#   STAGE      any of: data vae denoiser keymotion (default: all, in that order), and vae_decoder (after vae,
#              never by default: fine-tunes the VAE's decoder with the root term into WORK_DIR/vae_decoder) and
#              evaluator (never by default: the T2M evaluator on the denoiser's corpus into WORK_DIR/evaluator,
#              exported to WORK_DIR/evaluator_export; a candidate trained on a newer corpus is measured with it)
# Every stage resumes where it stopped when run again with RESUME=1 (Ctrl-C writes a checkpoint);
# the data stage skips what is already built (both builds are deterministic: the same commit and
# seed give byte-identical files, so a lost run folder is rebuilt from this recipe alone).
# Environment: VAE_CONFIG the VAE stage's config (default configs/general-vae.json: v2_vae.json plus the integrated-root
# term, extra weight on the root channels and bf16 autocast; lab/configs/v2_vae.json is the first v2 run's), DEN_CONFIG
# the denoiser's (default configs/salad-0.3/denoiser.json: v2_denoiser.json's recipe in 10,000 steps, lr x0.2 at 8,000, forward
# under bf16 autocast: 1.88x per step, measured; about 2.2 hours on 2 cores), VAE_STEPS, DEN_STEPS, VAE_DEC_STEPS override the configs' step budgets, KM_STEPS="KF_VAE PST MMAE" KeyMotion's
# (three numbers); PYTHON the python to use;
# DEN_DATA the denoiser's corpus (default: WORK_DIR/corpus, the VAE's). The first v2 run trained its VAE
# on corpus 2.0 (commit f1f8697) and its denoiser on corpus 2.1 (commit 33c5adb, DEN_DATA=WORK_DIR/corpus21):
# the denoiser normalises motions with the VAE's statistics, so any corpus of the same layout works.
# The v3 run (session of 2026-11-27, ~/salad-runs/v3) built its data at commit 197e7fc (corpus generator 2.4,
# 4,000 motions + mirrors; 4,000 general motions) and trained the VAE and the denoiser on it; later commits
# build newer corpora, so rebuild v3's data from a worktree of 197e7fc.
# KeyMotion (keyframe VAE, PST, MMAE: configs/keymotion-0.2.json, into WORK_DIR/keymotion) trains on the
# denoiser's corpus, DEN_DATA, so that both generators of the comparison saw the same motions and captions;
# it needs neither the VAE nor the denoiser and may run before them.
set -euo pipefail
cd "$(dirname "$0")/../../.."   # the repository
WORK=${1:-$HOME/salad-runs/v2}
shift || true
STAGES=${*:-data vae denoiser keymotion}
PY=${PYTHON:-.venv/bin/python}
RESUME=${RESUME:+--resume}
mkdir -p "$WORK"
# Long runs share the machine: OpenMP workers sleep between parallel regions (a 2-thread trainer whose
# workers spin fell from 1.6 to 0.05 steps/s when other sessions loaded the cores; docs/performance.md).
export SALAD_OMP_WAIT=${SALAD_OMP_WAIT:-passive}
has() { [[ " $STAGES " == *" $1 "* ]]; }

if has data; then
  # corpus 2.0 (default size: 4,000 motions and their mirrors) and 4,000 general motions
  [ -f "$WORK/corpus/corpus.json" ] || "$PY" -m salad_core.cli corpus build --out "$WORK/corpus" --size default --seed 0
  [ -f "$WORK/general/general.json" ] || "$PY" scripts/build_general_motion.py --out "$WORK/general" --n 4000 --seed 0
  git rev-parse HEAD > "$WORK/data.commit" 2>/dev/null || true
fi
if has vae; then
  # the skeleto-temporal VAE (paper architecture, 162,503 parameters) on corpus + general motion (ratio 0.5),
  # with the bone-length term, latent noise, the integrated-root term and bf16 autocast (configs/general-vae.json)
  "$PY" -m salad_core.train vae --data "$WORK/corpus" --general "$WORK/general" --out "$WORK/vae" \
      --config "${VAE_CONFIG:-configs/general-vae.json}" ${VAE_STEPS:+--steps "$VAE_STEPS"} --no-progress $RESUME
fi
if has vae_decoder; then
  # decoder fine-tuning with the integrated-root term (issue 21: the heading drifts): the v2 VAE's encoder is
  # frozen (its posteriors, which the denoiser learned, stay bit-identical) and its decoder learns lambda_root
  # (lab/configs/v2_vae_decoder.json). Not in the default stages; init_from is filled in here, as $WORK/vae.
  "$PY" - "$WORK" <<'PYEOF'
import json, sys
from pathlib import Path
work = Path(sys.argv[1])
doc = json.loads(Path("lab/configs/v2_vae_decoder.json").read_text())
doc["train"]["init_from"] = str((work / "vae").resolve())
(work / "vae_decoder.config.json").write_text(json.dumps(doc, indent=2) + "\n")
PYEOF
  "$PY" -m salad_core.train vae --data "$WORK/corpus" --general "$WORK/general" --out "$WORK/vae_decoder" \
      --config "$WORK/vae_decoder.config.json" ${VAE_DEC_STEPS:+--steps "$VAE_DEC_STEPS"} --no-progress $RESUME
fi
if has denoiser; then
  # DEN_VAE: the frozen VAE (default: this recipe's VAE run; on a machine that lost the run folder, the
  # shipped copy of the v3 VAE, salad_core/weights/general_vae/vae, gives the same latents)
  "$PY" -m salad_core.train denoiser --data "${DEN_DATA:-$WORK/corpus}" --out "$WORK/denoiser" --vae "${DEN_VAE:-$WORK/vae}" \
      --config "${DEN_CONFIG:-configs/salad-0.3/denoiser.json}" ${DEN_STEPS:+--steps "$DEN_STEPS"} --no-progress $RESUME
fi
if has evaluator; then
  # scripts/reproduce_evaluator.sh (the shipped evaluator's recipe, configs/evaluator.json), one thread: about 27
  # minutes beside another run; into WORK_DIR/evaluator, exported to WORK_DIR/evaluator_export
  CORPUS=${DEN_DATA:-$WORK/corpus} PYTHON=$PY bash scripts/reproduce_evaluator.sh "$WORK"
fi
if has keymotion; then
  # three stages in one process; a finished stage is skipped on RESUME=1, an interrupted one continues
  "$PY" -m salad_core.train keymotion --data "${DEN_DATA:-$WORK/corpus}" --out "$WORK/keymotion" \
      --config configs/keymotion-0.2.json ${KM_STEPS:+--steps-per-stage $KM_STEPS} --no-progress $RESUME
fi
