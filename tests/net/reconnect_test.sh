#!/usr/bin/env bash
# The server killed (SIGKILL, as a crash) and started again under running clients: a projector
# (--frames 0), a headset playing an orbit until stopped, and a load generator with two headsets
# (--seconds 0). Each must be served again within 15 s of the restart, without being restarted
# itself: new projector frames and headset layers on disk, and the clients' own counts of
# reconnects and of layers since the reconnect.
set -euo pipefail
bin="$1"
dir=$(mktemp -d)
pids=()
cleanup() { for p in "${pids[@]}" "${server:-}"; do kill -KILL "$p" 2>/dev/null || true; done; rm -rf "$dir"; }
trap cleanup EXIT
(umask 077 && echo "reconnect-test-token" > "$dir/token")
start_server() {
  "$bin/hysar" serve --listen 127.0.0.1:0 --unix "$dir/s.sock" --token-file "$dir/token" >> "$dir/serve.log" 2>&1 &
  server=$!
  for _ in $(seq 200); do [[ -S "$dir/s.sock" ]] && return 0; sleep 0.1; done
  echo "the server did not start"; cat "$dir/serve.log"; exit 1
}
# Waits up to 15 s for a file matching the glob $1 in a folder emptied at the restart.
served_again() {
  for _ in $(seq 150); do compgen -G "$1" > /dev/null && return 0; sleep 0.1; done
  echo "not served again within 15 s: no $1"; tail -5 "$dir"/*.log; exit 1
}
start_server
common=(--connect "unix:$dir/s.sock" --token-file "$dir/token" --backoff-ms 100)
mkdir "$dir/p" "$dir/h"
"$bin/clients/hysar-projector" "${common[@]}" --frames 0 --out "$dir/p" > "$dir/projector.log" 2>&1 &
projector=$!
pids+=($projector)
"$bin/clients/hysar-hmd" "${common[@]}" --orbit 4 --frames 0 --scale 0.25 --name orbit \
  --out "$dir/h" --summary "$dir/hmd.json" > "$dir/hmd.log" 2>&1 &
hmd=$!
pids+=($hmd)
"$bin/clients/hysar-loadgen" "${common[@]}" --viewers 2 --seconds 0 --json "$dir/loadgen.json" \
  > "$dir/loadgen.log" 2>&1 &
loadgen=$!
pids+=($loadgen)
served_again "$dir/p/projector_v*.png"
served_again "$dir/h/orbit_*_right.png"
sleep 1

kill -KILL "$server"
wait "$server" 2>/dev/null || true
rm -f "$dir"/p/* "$dir"/h/*
sleep 1
start_server
restarted=$(date +%s.%N)
served_again "$dir/p/projector_v*.png"
served_again "$dir/h/orbit_*_right.png"
echo "projector and headset served again $(python3 -c "import time; print(f'{time.time() - $restarted:.1f}')") s after the restart"
sleep 2
kill -TERM "$hmd" "$loadgen" "$projector"
wait "$projector" || { echo "hysar-projector exit $?"; cat "$dir/projector.log"; exit 1; }
wait "$hmd" || { echo "hysar-hmd exit $?"; cat "$dir/hmd.log"; exit 1; }
wait "$loadgen" || { echo "hysar-loadgen exit $?"; cat "$dir/loadgen.log"; exit 1; }
kill -TERM "$server" && wait "$server" 2>/dev/null || true
grep -q "reconnected" "$dir/projector.log" || { echo "the projector did not report a reconnect"; cat "$dir/projector.log"; exit 1; }
python3 - "$dir/hmd.json" "$dir/loadgen.json" <<'PY'
import json, sys
hmd = json.load(open(sys.argv[1]))
assert hmd["reconnects"] >= 1, f"hysar-hmd counted {hmd['reconnects']} reconnects"
lg = json.load(open(sys.argv[2]))
for v in lg["per_viewer"]:
    assert v["reconnects"] >= 1, f"loadgen viewer {v['viewer']}: no reconnect"
    assert v["layers_since_reconnect"] > 0, f"loadgen viewer {v['viewer']}: no layer after it"
print("reconnect test: headset", hmd["reconnects"], "reconnect(s);", "loadgen viewers",
      [(v["reconnects"], v["layers_since_reconnect"]) for v in lg["per_viewer"]])
PY
