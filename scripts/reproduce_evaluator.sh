#!/usr/bin/env bash
# Reproduce the shipped T2M evaluator for the procedural corpus (salad_core/weights/evaluator).
#
# Usage: bash scripts/reproduce_evaluator.sh [--dry-run] [OUT]     (default OUT: runs/reproduce/evaluator)
#   --dry-run   print the commands and run nothing
#   RESUME=1    continue an interrupted run (Ctrl-C writes a checkpoint)
#   PYTHON      the python to use (default .venv/bin/python)
#
# Stages: the procedural corpus (size default, seed 0), then salad_core.eval.train_evaluator with the options of
# configs/evaluator.json (a snippet autoencoder, 1,000 steps, then contrastive matching, 4,000 steps; about 30
# minutes on one thread), exported with its model card to OUT/evaluator_export. Everything is written under OUT;
# an OUT inside salad_core/weights is refused. CORPUS=DIR uses a corpus built before, as it is. The shipped evaluator
# learnt corpus generator 2.4 (commit 197e7fc): scripts/reproduce_salad.sh's header says how to build it.
#
# The recipe is T2M's with three changes (salad_core/eval/train_evaluator.py): widths of 128 (0.78 M
# parameters), Adam lr 1e-3 instead of 1e-4, MiniLM word vectors in contextual mode instead of GloVe.
set -euo pipefail
cd "$(dirname "$0")/.."
DRY=0
if [ "${1:-}" = "--dry-run" ]; then DRY=1; shift; fi
OUT=${1:-runs/reproduce/evaluator}
PY=${PYTHON:-.venv/bin/python}
RESUME=${RESUME:+--resume}
case "$(realpath -m "$OUT")/" in "$(realpath -m salad_core/weights)"/*)
  echo "refusing to write into the shipped weights ($OUT): give a folder outside salad_core/weights" >&2; exit 2;; esac
run() { if [ "$DRY" = 1 ]; then printf "%q " "$@"; echo; else echo "+ $*"; "$@"; fi; }
CONFIG=configs/evaluator.json
[ "$DRY" = 1 ] || mkdir -p "$OUT"
if [ -z "${CORPUS:-}" ]; then    # a given CORPUS is used as it is
  CORPUS=$OUT/corpus
  [ -f "$CORPUS/corpus.json" ] || run "$PY" -m salad_core.cli corpus build --out "$CORPUS" --size default --seed 0
fi
# the options of configs/evaluator.json ("args"), as command-line options
mapfile -t ARGS < <(python3 -c 'import json, sys
for k, v in json.load(open(sys.argv[1]))["args"].items(): print(f"--{k}"); print(v)' "$CONFIG")
run "$PY" -m salad_core.eval.train_evaluator --data "$CORPUS" --out "$OUT/evaluator" "${ARGS[@]}" \
    --no-progress $RESUME --export "$OUT/evaluator_export"
