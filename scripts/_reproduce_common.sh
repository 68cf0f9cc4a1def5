# The shared start of the scripts/reproduce_*.sh scripts: sourced (not run), from the repository root, as
#   source scripts/_reproduce_common.sh DEFAULT_OUT "$@"
# It reads the script's arguments [--dry-run] [OUT] and sets
#   DRY      1 with --dry-run (print the commands, run nothing), else 0
#   OUT      the output folder (default DEFAULT_OUT); one inside salad_core/weights is refused (exit 2)
#   PY       the python to use: PYTHON, default .venv/bin/python
#   RESUME   --resume when RESUME is set, else empty
# creates OUT (not in a dry run) and defines run (run a command, or print it in a dry run), corpus_data and
# general_data (the data stages).
_default_out=$1
shift
DRY=0
if [ "${1:-}" = "--dry-run" ]; then DRY=1; shift; fi
OUT=${1:-$_default_out}
PY=${PYTHON:-.venv/bin/python}
RESUME=${RESUME:+--resume}
case "$(realpath -m "$OUT")/" in "$(realpath -m salad_core/weights)"/*)
  echo "refusing to write into the shipped weights ($OUT): give a folder outside salad_core/weights" >&2; exit 2;; esac
run() { if [ "$DRY" = 1 ]; then printf "%q " "$@"; echo; else echo "+ $*"; "$@"; fi; }
[ "$DRY" = 1 ] || mkdir -p "$OUT"

# CORPUS: the procedural corpus (size default, seed 0) in OUT/corpus, built unless it is there; a given
# CORPUS is used as it is.
corpus_data() {
  if [ -z "${CORPUS:-}" ]; then
    CORPUS=$OUT/corpus
    [ -f "$CORPUS/corpus.json" ] || run "$PY" -m salad_core.cli corpus build --out "$CORPUS" --size default --seed 0
  fi
}

# GENERAL: 4,000 general motions (seed 0) in OUT/general, built unless they are there; a given GENERAL is
# used as it is.
general_data() {
  if [ -z "${GENERAL:-}" ]; then
    GENERAL=$OUT/general
    [ -f "$GENERAL/general.json" ] || run "$PY" scripts/build_general_motion.py --out "$GENERAL" --n 4000 --seed 0
  fi
}
