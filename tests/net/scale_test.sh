#!/usr/bin/env bash
# Viewer-count scale test: hysar serve on a Unix socket, hysar-loadgen at 1, 8 and 32 headsets
# for a few seconds each. Asserts no errors and every headset served (loadgen exits 1
# otherwise); the throughput tables stay in the test log. Timing targets live in benchmarks.
set -euo pipefail
bin="$1"        # build folder
seconds="${2:-3}"
dir=$(mktemp -d)
on_exit() {
  rc=$?
  kill -TERM "$server" 2>/dev/null || true
  if [[ $rc -ne 0 && -f "$dir/serve.log" ]]; then echo "--- server log (last 40 lines) ---"; tail -40 "$dir/serve.log"; fi
  rm -rf "$dir"
}
trap on_exit EXIT
(umask 077 && echo "scale-test-token" > "$dir/token")
HYSAR_VALIDATION=1 "$bin/hysar" serve --listen 127.0.0.1:0 --unix "$dir/hysar.sock" --token-file "$dir/token" \
  --stats-file "$dir/stats.json" > "$dir/serve.log" 2>&1 &
server=$!
for _ in $(seq 100); do [[ -S "$dir/hysar.sock" ]] && break; sleep 0.1; done
[[ -S "$dir/hysar.sock" ]] || { echo "the server did not start:"; cat "$dir/serve.log"; exit 1; }
# The socket opens before the first scene version is built and warmed up (2-3 s under
# AddressSanitizer, as long as the first run): the runs below measure serving, so they wait.
for _ in $(seq 1200); do grep -q "warm-up:" "$dir/serve.log" && break; sleep 0.1; done
grep -q "warm-up:" "$dir/serve.log" || { echo "the server did not warm up:"; cat "$dir/serve.log"; exit 1; }
for n in 1 8 32; do
  # Every headset must get a frame: 32 of them share one renderer, and on a slow machine (or
  # under AddressSanitizer) one round over all of them takes several seconds, so they get
  # three times as long.
  run_s=$seconds
  [[ $n -eq 32 ]] && run_s=$((seconds * 3))
  echo "--- hysar-loadgen --viewers $n --seconds $run_s ---"
  "$bin/clients/hysar-loadgen" --connect "unix:$dir/hysar.sock" --token-file "$dir/token" \
    --viewers "$n" --rate 30 --seconds "$run_s" --json "$dir/loadgen_$n.json"
done
kill -TERM "$server"
for _ in $(seq 100); do kill -0 "$server" 2>/dev/null || break; sleep 0.1; done
if kill -0 "$server" 2>/dev/null; then echo "the server did not stop on SIGTERM"; exit 1; fi
wait "$server" || { echo "the server exited with an error:"; tail -20 "$dir/serve.log"; exit 1; }
grep -q '"projector_renders": 1' "$dir/stats.json" || { echo "projector rendered more than once"; cat "$dir/stats.json"; exit 1; }
if grep -q "validation" "$dir/serve.log"; then echo "Vulkan validation messages:"; grep validation "$dir/serve.log"; exit 1; fi
echo "scale test: 1, 8 and 32 headsets served, no errors"
