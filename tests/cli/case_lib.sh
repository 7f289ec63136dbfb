# Sourced by the command-line tests: one way to run a case and judge it.
#
# expect NAME WANT_RC STREAM PATTERNS COMMAND...
#   Runs COMMAND in the current folder (stdin from /dev/null, at most CASE_TIMEOUT seconds,
#   default 60), stdout into out.log and stderr into err.log. It passes when the exit status
#   matches WANT_RC (an extended regular expression: 2, or 0|1), when STREAM (err: stderr;
#   all: stdout and stderr) holds every non-empty line of PATTERNS (grep -E, or fixed strings
#   when CASE_GREP=-F) and is not empty if PATTERNS is not, and when nothing speaks of an abort
#   or an internal error. Prints "ok" or "FAIL" with the reason and the output's head.
# finish: prints the totals; its status is non-zero when a case failed.
failures=0
cases=0

expect() {
  local name="$1" want="$2" stream="$3" patterns="$4"
  shift 4
  cases=$((cases + 1))
  timeout "${CASE_TIMEOUT:-60}" "$@" > out.log 2> err.log < /dev/null
  local rc=$?
  local logs=(err.log)
  [ "$stream" = all ] && logs=(out.log err.log)
  local why=""
  if ! [[ "$rc" =~ ^($want)$ ]]; then
    why="exit status $rc, expected $want"
  elif [ -n "$patterns" ] && [ -z "$(cat "${logs[@]}")" ]; then
    why="no output"
  else
    while IFS= read -r p; do
      [ -z "$p" ] && continue
      if ! cat "${logs[@]}" | grep -q "${CASE_GREP:--E}" -- "$p"; then
        why="the output does not hold '$p'"
        break
      fi
    done <<< "$patterns"
  fi
  if [ -z "$why" ] && grep -qE "terminate called|Aborted|Segmentation|internal error|what\(\)" out.log err.log; then
    why="the output speaks of an abort or an internal error"
  fi
  if [ -n "$why" ]; then
    failures=$((failures + 1))
    echo "FAIL $name: $why"
    echo "  command: $*"
    cat "${logs[@]}" | sed 's/^/  | /' | head -20
  else
    echo "ok   $name: $(cat "${logs[@]}" | head -1)"
  fi
}

finish() {
  echo "$cases cases, $failures failed"
  [ "$failures" -eq 0 ]
}
