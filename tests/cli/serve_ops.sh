#!/usr/bin/env bash
# `hysar serve` as an operator runs it: token files (mode, CRLF), SIGHUP reloads (a broken file
# keeps the running scene), running out of descriptors under prlimit, SIGTERM with the final
# stats, and a scene file with an out-of-range number. Loopback only.
# Usage: serve_ops.sh BUILD_DIR SOURCE_DIR
set -uo pipefail
build=$1 src=$2
hysar=$build/hysar hmd=$build/clients/hysar-hmd
dir=$(mktemp -d)
server=
cleanup() { [[ -n $server ]] && kill -KILL "$server" 2>/dev/null; rm -rf "$dir"; }
trap cleanup EXIT
fail() { echo "serve_ops: FAIL: $*"; [[ -f $dir/serve.log ]] && sed 's/^/  log: /' "$dir/serve.log"; exit 1; }
small_scene() { # the default room with a small projector, so each render is quick
  sed -e 's/"width": *1920, *"height": *1200, *"fx": *3000, *"fy": *3000, *"cx": *959.5, *"cy": *599.5/"width": 480, "height": 300, "fx": 750, "fy": 750, "cx": 239.5, "cy": 149.5/' \
    "$src/configs/exp1-room.json" > "$1"
  grep -q '"width": 480' "$1" || fail "could not shrink the projector of configs/exp1-room.json"
}

# A token file others can read is refused, naming the fix.
printf 'secret\n' > "$dir/open-token"; chmod 644 "$dir/open-token"
out=$("$hysar" serve --token-file "$dir/open-token" --listen 127.0.0.1:0 2>&1); rc=$?
[[ $rc -eq 1 && $out == *"chmod 600"* ]] || fail "a world-readable token file: rc $rc: $out"

# A scene file with a number out of double range: a clear error, not an abort.
small_scene "$dir/room.json"
sed 's/"name"/"big": 1e999, "name"/' "$dir/room.json" > "$dir/huge.json"
out=$("$hysar" render --scene "$dir/huge.json" --out "$dir/r" --no-reference 2>&1); rc=$?
[[ $rc -ne 0 && $rc -lt 128 && $out == *huge.json* ]] || fail "1e999 in a scene: rc $rc: $out"

# The server with a CRLF token file, under a descriptor limit of 64. Its cap on connections
# owing Hello (32 by default) would keep silent connections from ever filling the table, so it
# is raised here past the limit to make accept() fail.
(umask 077 && printf 'secret\r\n' > "$dir/token" && printf 'admin-secret\n' > "$dir/admin-token")
prlimit --nofile=64:64 "$hysar" serve --scene "$dir/room.json" --listen 127.0.0.1:0 --max-pending 200 \
  --token-file "$dir/token" --admin-token-file "$dir/admin-token" \
  --stats-file "$dir/stats.json" > "$dir/serve.log" 2>&1 &
server=$!
for _ in $(seq 200); do grep -q "serving" "$dir/serve.log" && break; sleep 0.1; done
port=$(sed -n 's/.* on 127\.0\.0\.1:\([0-9]*\).*/\1/p' "$dir/serve.log" | head -1)
[[ -n $port ]] || fail "the server did not start"
still() { "$hmd" --connect "127.0.0.1:$port" --token-file "$dir/token" --angles "$1" --scale 0.125 \
  --out "$dir/hmd" --name "$2" > "$dir/hmd-$2.log" 2>&1; }
still 0 first || fail "a headset with the CRLF token: $(cat "$dir/hmd-first.log")"

# More connections than descriptors: accept fails with EMFILE, then recovers.
fds=()
for _ in $(seq 80); do exec {fd}<>"/dev/tcp/127.0.0.1/$port" 2>/dev/null && fds+=("$fd"); done
sleep 1
for fd in "${fds[@]}"; do exec {fd}>&-; done
grep -q "accept on TCP failed" "$dir/serve.log" || fail "the server never ran out of descriptors (${#fds[@]} opened)"
kill -0 "$server" 2>/dev/null || fail "the server died after EMFILE"
still 20 after-emfile || fail "no headset served after EMFILE: $(cat "$dir/hmd-after-emfile.log")"

# SIGHUP: a broken scene file is reported and the running scene stays; a good one is applied.
cp "$dir/room.json" "$dir/room.good"
echo '{ broken' > "$dir/room.json"
kill -HUP "$server"
for _ in $(seq 100); do grep -q "running scene stays" "$dir/serve.log" && break; sleep 0.1; done
grep -q "running scene stays" "$dir/serve.log" || fail "SIGHUP with a broken file was not reported"
kill -0 "$server" 2>/dev/null || fail "SIGHUP killed the server"
sed 's/"albedo": *\[[^]]*\]/"albedo": [0.2, 0.6, 0.9]/' "$dir/room.good" > "$dir/room.json"
kill -HUP "$server"
for _ in $(seq 300); do grep -q "scene version 2" "$dir/serve.log" && break; sleep 0.1; done
grep -q "scene version 2" "$dir/serve.log" || fail "SIGHUP did not reload the scene"
still -20 after-reload || fail "no headset served after the reload"

# SIGTERM: exit 0, and the final stats keep every viewer's figures.
kill -TERM "$server"
wait "$server"; rc=$?; server=
[[ $rc -eq 0 ]] || fail "SIGTERM: exit code $rc"
python3 - "$dir/stats.json" <<'PY' || fail "final stats: $(cat "$dir/stats.json")"
import json, sys
s = json.load(open(sys.argv[1]))
v = [x for x in s["viewers"] if x["frames"] > 0]
assert len(v) >= 3, s["viewers"]
assert s["scene_version"] == 2 and s["projector_renders"] == 2, s
PY
echo "serve_ops: token files, SIGHUP, EMFILE under prlimit, SIGTERM stats: all as documented"
echo "1 passed, 0 failed"
