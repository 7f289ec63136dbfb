#!/usr/bin/env bash
# hysar's log lines (docs/OPERATIONS.md, "Logs"): text lines carry a UTC timestamp and the level;
# --log-level warn hides info lines and debug shows debug lines; --log-format json writes one
# JSON object per line with ts, level and msg, and session on a session's lines; flags override
# HYSAR_LOG_LEVEL; a bad level, format, variable or HYSAR_DEVICE exits 2 naming it. The server
# cases run `hysar serve` on loopback with a small projector and one headset still.
# Usage: log_cli.sh BUILD_DIR SOURCE_DIR
set -uo pipefail
build=$1 src=$2
hysar=$build/hysar hmd=$build/clients/hysar-hmd
dir=$(mktemp -d)
server=
cleanup() { [[ -n $server ]] && kill -KILL "$server" 2>/dev/null; rm -rf "$dir"; }
trap cleanup EXIT
unset HYSAR_LOG_LEVEL HYSAR_LOG_FORMAT HYSAR_DEVICE
passed=0
fail() { echo "log_cli: FAIL: $*"; exit 1; }
ok() { passed=$((passed + 1)); echo "ok: $*"; }
ts='[0-9]{4}-[0-9]{2}-[0-9]{2}T[0-9]{2}:[0-9]{2}:[0-9]{2}\.[0-9]{3}Z'

# Refusals: exit 2 and one line naming the flag or variable, the value and the accepted values.
refused() { # NAME PATTERN... -- COMMAND...
  local name=$1; shift
  local patterns=()
  while [[ $1 != -- ]]; do patterns+=("$1"); shift; done
  shift
  "$@" > "$dir/out" 2> "$dir/err" < /dev/null; local rc=$?
  [[ $rc -eq 2 ]] || fail "$name: exit status $rc, expected 2: $(cat "$dir/err")"
  for p in "${patterns[@]}"; do
    grep -qF -- "$p" "$dir/err" || fail "$name: stderr does not name '$p': $(cat "$dir/err")"
  done
  ok "$name"
}
refused "--log-level bogus" --log-level "'bogus'" "debug, info, warn, error, off" -- \
  "$hysar" --log-level bogus eval optics
refused "--log-format=xml after the command" --log-format "'xml'" "text, json" -- \
  "$hysar" eval optics --log-format=xml
refused "--log-level without a value" --log-level -- "$hysar" eval optics --log-level
refused "HYSAR_LOG_LEVEL=loud" HYSAR_LOG_LEVEL "'loud'" -- env HYSAR_LOG_LEVEL=loud "$hysar" eval optics
refused "HYSAR_LOG_FORMAT=yaml" HYSAR_LOG_FORMAT "'yaml'" -- env HYSAR_LOG_FORMAT=yaml "$hysar" eval optics
refused "HYSAR_DEVICE=bogus" HYSAR_DEVICE "'bogus'" "auto, cpu, gpu" -- env HYSAR_DEVICE=bogus "$hysar" eval optics
refused "HYSAR_DEVICE=bogus --version" HYSAR_DEVICE -- env HYSAR_DEVICE=bogus "$hysar" --version

# Levels without a server: an error line (a bad option of eval optics) and main's debug line.
"$hysar" eval optics --no-such-option > /dev/null 2> "$dir/err"
grep -qE "^$ts error  ?unknown option '--no-such-option'" "$dir/err" ||
  fail "an error line with timestamp and level: $(cat "$dir/err")"
grep -qE " debug " "$dir/err" && fail "a debug line at the default level: $(cat "$dir/err")"
ok "text error line: timestamp, level, message; no debug line by default"
"$hysar" --log-level debug eval optics > /dev/null 2> "$dir/err" || fail "eval optics at debug"
grep -qE "^$ts debug hysar [0-9.]+ \(commit " "$dir/err" || fail "--log-level debug shows no debug line: $(cat "$dir/err")"
HYSAR_LOG_LEVEL=debug "$hysar" eval optics > /dev/null 2> "$dir/err"
grep -qE "^$ts debug " "$dir/err" || fail "HYSAR_LOG_LEVEL=debug shows no debug line"
HYSAR_LOG_LEVEL=debug "$hysar" eval optics --log-level info > /dev/null 2> "$dir/err"
grep -qE " debug " "$dir/err" && fail "--log-level info does not override HYSAR_LOG_LEVEL=debug"
ok "debug lines at --log-level debug and HYSAR_LOG_LEVEL=debug; the flag wins over the variable"
"$hysar" --log-level off eval optics --no-such-option > /dev/null 2> "$dir/err"
[[ ! -s $dir/err ]] || fail "--log-level off still logs: $(cat "$dir/err")"
ok "--log-level off: nothing"

# The server: one headset still, then SIGTERM. serve LOG ARGS... leaves its stderr in LOG.
sed -e 's/"width": *1920, *"height": *1200, *"fx": *3000, *"fy": *3000, *"cx": *959.5, *"cy": *599.5/"width": 480, "height": 300, "fx": 750, "fy": 750, "cx": 239.5, "cy": 149.5/' \
  "$src/configs/exp1-room.json" > "$dir/room.json"
(umask 077 && printf 'secret\n' > "$dir/token")
serve() {
  local log=$1; shift
  "$hysar" "$@" serve --scene "$dir/room.json" --listen 127.0.0.1:0 --token-file "$dir/token" \
    > "$dir/serve.out" 2> "$log" &
  server=$!
  for _ in $(seq 600); do grep -q "serving" "$dir/serve.out" && break; sleep 0.1; done
  local port
  port=$(sed -n 's/.* on 127\.0\.0\.1:\([0-9]*\).*/\1/p' "$dir/serve.out" | head -1)
  [[ -n $port ]] || fail "the server did not start: $(cat "$dir/serve.out" "$log")"
  "$hmd" --connect "127.0.0.1:$port" --token-file "$dir/token" --angles 0 --scale 0.125 \
    --out "$dir/hmd" --name 'still "one"' > "$dir/hmd.log" 2>&1 || fail "the headset: $(cat "$dir/hmd.log")"
  # The server logs the session's end once it sees the headset's connection close.
  for _ in $(seq 100); do grep -q "left" "$log" && break; sleep 0.1; done
  kill -TERM "$server"; wait "$server"; local rc=$?; server=
  [[ $rc -eq 0 ]] || fail "serve $*: exit status $rc: $(cat "$log")"
}

serve "$dir/text.log"
grep -qE "^$ts info  session [0-9]+: headset 'still \"one\"' joined$" "$dir/text.log" ||
  fail "text: no session line with timestamp and level: $(cat "$dir/text.log")"
grep -qE "^$ts info  session [0-9]+: left$" "$dir/text.log" || fail "text: no 'left' line: $(cat "$dir/text.log")"
bad=$(grep -vE "^$ts (debug|info |warn |error) " "$dir/text.log" | head -3)
[[ -z $bad ]] || fail "text: lines without timestamp and level: $bad"
ok "serve, text: every line has a timestamp and a level; session lines name the session"

serve "$dir/warn.log" --log-level warn
grep -qE " info  " "$dir/warn.log" && fail "--log-level warn: info lines: $(cat "$dir/warn.log")"
ok "serve --log-level warn: no info line"

serve "$dir/json.log" --log-format json --log-level debug
python3 - "$dir/json.log" <<'PY' || fail "json: $(head -5 "$dir/json.log")"
import json, re, sys
lines = open(sys.argv[1], encoding="utf-8").read().splitlines()
assert lines, "no lines"
levels, joined = set(), None
for line in lines:
    j = json.loads(line)
    assert set(j) >= {"ts", "level", "msg"}, line
    assert re.fullmatch(r"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d\.\d{3}Z", j["ts"]), line
    assert j["level"] in ("debug", "info", "warn", "error"), line
    assert set(j) <= {"ts", "level", "msg", "session", "session_name"}, line
    levels.add(j["level"])
    if j["msg"] == "headset 'still \"one\"' joined":
        joined = j
assert "debug" in levels and "info" in levels, levels
assert joined and isinstance(joined.get("session"), int) and joined["session"] > 0, joined
left = [json.loads(l) for l in lines if json.loads(l)["msg"] == "left"]
assert left and left[0]["session"] == joined["session"], left
print(f"json: {len(lines)} lines, levels {sorted(levels)}, session {joined['session']}")
PY
ok "serve --log-format json --log-level debug: every line is JSON with ts, level, msg; session lines carry the session"

echo "$passed passed, 0 failed"
