# Shared by the resumable evaluation scripts (evaluate_candidate.sh, evaluate_keymotion.sh); sourced, not run.
# The caller sets OUT (results folder) and STAGES (the stages asked for, space-separated).
has() { [[ " $STAGES " == *" $1 "* ]]; }
stage() {  # stage NAME CMD...: run CMD unless NAME is done, log its output and time
  local name=$1; shift
  if [ -f "$OUT/$name.done" ]; then echo "[$name] done before ($(cat "$OUT/$name.done")): skipped"; return; fi
  echo "[$name] $(date -u +%FT%TZ): $*"
  local t0=$SECONDS
  "$@" 2>&1 | tee "$OUT/$name.log"
  echo "$(date -u +%FT%TZ), $((SECONDS - t0)) s" > "$OUT/$name.done"
  echo "[$name] finished in $((SECONDS - t0)) s"
}
