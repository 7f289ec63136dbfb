#!/usr/bin/env bash
# `hysar admin` against a running server with two headsets: viewers lists both, projectors the
# scene's projector served by one client, stats prints a
# table (twice with --watch/--count) and --json the server's JSON, scene push applies a changed
# scene (a newer scene version, and the projector gets its frame), a broken scene file is refused
# before anything is sent, a scene the server refuses comes back with its error (exit 1), kick
# closes one headset (the other is served on), and a wrong token, an unreachable server and bad
# arguments exit 2 with a sentence.
set -euo pipefail
bin="$1" src="$2"
dir=$(mktemp -d)
pids=()
cleanup() { for p in "${pids[@]}"; do kill -KILL "$p" 2>/dev/null || true; done; rm -rf "$dir"; }
trap cleanup EXIT
fail() { echo "admin test: $*" >&2; exit 1; }
(umask 077 && echo "admin-test-viewers" > "$dir/token" && echo "admin-test-admin" > "$dir/admin")
# The server refuses scenes over 40,000 triangles: the default 256 x 64 dome fits, 512 x 64 not.
"$bin/hysar" serve --listen 127.0.0.1:0 --unix "$dir/s.sock" --token-file "$dir/token" \
  --admin-token-file "$dir/admin" --max-triangles 40000 > "$dir/serve.log" 2>&1 &
pids+=($!); disown
for _ in $(seq 200); do [[ -S "$dir/s.sock" ]] && break; sleep 0.1; done
[[ -S "$dir/s.sock" ]] || { cat "$dir/serve.log"; fail "the server did not start"; }
"$bin/clients/hysar-loadgen" --connect "unix:$dir/s.sock" --token-file "$dir/token" --viewers 2 \
  --seconds 0 > "$dir/loadgen.log" 2>&1 &
pids+=($!); disown
mkdir "$dir/p"
"$bin/clients/hysar-projector" --connect "unix:$dir/s.sock" --token-file "$dir/token" --frames 0 \
  --out "$dir/p" > "$dir/projector.log" 2>&1 &
pids+=($!); disown
# A headset whose name carries a terminal escape sequence and a newline (a client of its own
# making): the server's log and the table must show them as text, never pass them on.
python3 - "$dir/s.sock" "$dir/token" <<'PY' > "$dir/raw.log" 2>&1 &
import socket, struct, sys, time
def frame(t, payload):
    return struct.pack("<IHHII", 0x52535948, 1, t, len(payload), 0) + payload
def s16(b):
    return struct.pack("<H", len(b)) + b
token = open(sys.argv[2], "rb").read().strip()
s = socket.socket(socket.AF_UNIX)
s.connect(sys.argv[1])
s.sendall(frame(1, bytes([2]) + s16(token) + s16(b"\x1b[2Jevil\xc2\x9b\nFORGED")))
s.sendall(frame(3, struct.pack("<IIdddddBBB", 320, 180, 300.0, 300.0, 160.0, 90.0, 0.063, 1, 2, 1)))
time.sleep(600)
PY
pids+=($!); disown
admin=("$bin/hysar" admin --connect "unix:$dir/s.sock" --token-file "$dir/admin" --timeout-ms 60000)

# Both headsets with frames and the raw client's headset, once they are all there (60 s at most).
for _ in $(seq 300); do
  out=$("${admin[@]}" viewers)
  [[ $(echo "$out" | awk 'NR > 1 && $4 > 0' | wc -l) -ge 2 ]] && echo "$out" | grep -q "evil" && break
  sleep 0.2
done
echo "$out"
echo "$out" | head -1 | grep -q "session.*name.*frames.*p50 ms" || fail "viewers: no header"
[[ $(echo "$out" | awk 'NR > 1 && $4 > 0' | wc -l) -eq 2 ]] || fail "viewers: not two headsets with frames"
echo "$out" | grep -q "?\[2Jevil?" || fail "viewers: the escaped name is not shown as ?[2Jevil?"
if echo "$out" | grep -q $'\x1b'; then fail "viewers: an escape character reached the terminal"; fi
# The server itself keeps the name's control characters out of its log: no forged line.
grep -q "'?\[2Jevil??FORGED' joined" "$dir/serve.log" || { cat "$dir/serve.log"; fail "serve log: the name is not shown as ?[2Jevil??FORGED"; }
if grep -q "^FORGED" "$dir/serve.log" || grep -q $'\x1b' "$dir/serve.log"; then fail "serve log: the name's newline or escape reached the log"; fi

# The scene's projector, served by the projector client above.
for _ in $(seq 150); do
  out=$("${admin[@]}" projectors)
  echo "$out" | grep -q " yes  *1 " && break
  sleep 0.2
done
echo "$out"
echo "$out" | head -1 | grep -q "projector.*connected.*clients.*blended" || fail "projectors: no header"
echo "$out" | grep -q "^Epson EB-U32 (ceiling)  *yes  *1 " || fail "projectors: the scene's projector is not shown served by one client"

out=$("${admin[@]}" stats --watch 0.2 --count 2)
[[ $(echo "$out" | grep -c "^scene version") -eq 2 ]] || { echo "$out"; fail "stats --watch 0.2 --count 2: not two tables"; }
echo "$out" | grep -q "^stage pass ms (mean) *[0-9]" || { echo "$out"; fail "stats: no pass cost"; }
"${admin[@]}" stats --json | python3 -c "
import json, sys
s = json.load(sys.stdin)
assert s['scene_version'] == 1, s['scene_version']
assert sum(1 for v in s['viewers'] if v['frames'] > 0) == 2, s['viewers']
" || fail "stats --json"

# A changed scene: applied, and the projector receives version 2.
python3 - "$src/configs/exp1-room.json" "$dir/room2.json" "$dir/big.json" <<'PY'
import json, sys
s = json.load(open(sys.argv[1]))
s["name"] = "admin test, version 2"
json.dump(s, open(sys.argv[2], "w"))
s["prop"]["segments"] = 512
json.dump(s, open(sys.argv[3], "w"))
PY
out=$("${admin[@]}" scene push "$dir/room2.json")
echo "$out"
echo "$out" | grep -q "applied: scene version 2 (was 1)" || fail "scene push: not applied as version 2"
for _ in $(seq 100); do compgen -G "$dir/p/projector_v2*" > /dev/null && break; sleep 0.1; done
compgen -G "$dir/p/projector_v2*" > /dev/null || fail "the projector did not receive version 2"

# The refusals, each a case of tests/cli/case_lib.sh (exit status and the sentence on stderr).
source "$src/tests/cli/case_lib.sh"
set +e  # a case's command may fail: expect judges its status
cd "$dir"
# Refused by the server (over its --max-triangles): exit 1 with the server's sentence.
expect "a scene over the server's limits" 1 err "the server refused the scene: .*triangles" \
  "${admin[@]}" scene push "$dir/big.json"
# Refused here: broken JSON never reaches the server (its version stays 2).
echo '{"schema_version": 1, "prop": ' > "$dir/broken.json"
expect "a broken scene file" 2 err "scene push $dir/broken.json: .*malformed JSON" \
  "${admin[@]}" scene push "$dir/broken.json"
v=$("${admin[@]}" stats --json | python3 -c "import json, sys; print(json.load(sys.stdin)['scene_version'])")
[[ $v -eq 2 ]] || fail "scene version $v after the refused pushes, expected 2"
# Wrong token, no server, bad arguments: exit 2, one sentence each.
expect "the viewers' token as admin" 2 err "admin session: the server refused the session: unauthorized" \
  "$bin/hysar" admin --connect "unix:$dir/s.sock" --token-file "$dir/token" viewers
expect "no server" 2 err "^hysar admin: --connect: " \
  "$bin/hysar" admin --connect "unix:$dir/none.sock" --token-file "$dir/admin" viewers
expect "unknown command" 2 err "unknown command 'restart'" "${admin[@]}" restart
expect "no command" 2 err "no command" "${admin[@]}"
expect "scene push without a file" 2 err "scene push needs one FILE" "${admin[@]}" scene push
expect "--watch on viewers" 2 err "go with the stats command" "${admin[@]}" viewers --watch 1
expect "--watch 0" 2 err "--watch: '0' is outside \[0\.2, 3600\]" "${admin[@]}" stats --watch 0
# kick: a headset by name, told why (the server's log says who asked and why); again, it is
# gone; bad arguments.
expect "kick by name" 0 all "^closed session [0-9]+ \(loadgen-1\)" \
  "${admin[@]}" kick loadgen-1 --reason "lens check"
expect "kick of a closed session" 1 err "no connected headset has the name 'loadgen-1'" \
  "${admin[@]}" kick loadgen-1
expect "kick without a viewer" 2 err "kick needs one VIEWER" "${admin[@]}" kick
expect "--reason on viewers" 2 err "--reason goes with the kick command" \
  "${admin[@]}" viewers --reason x
finish || fail "a refusal is not as documented"
grep -q "closing session [0-9]* (loadgen-1) at an operator's request: lens check" "$dir/serve.log" ||
  fail "kick: the server's log does not say who was closed and why"
out=$("${admin[@]}" viewers)
[[ $(echo "$out" | awk '$2 == "loadgen-1" && $3 == "yes"' | wc -l) -eq 0 ]] ||
  fail "kick: loadgen-1 is still connected: $out"
[[ $(echo "$out" | awk '$2 == "loadgen-0" && $3 == "yes"' | wc -l) -eq 1 ]] ||
  fail "kick: loadgen-0 was not served on: $out"
"$bin/hysar" admin --help | grep -q "^usage: hysar admin" || fail "--help"
echo "admin test: viewers, stats, scene push, kick and every refusal as documented"
