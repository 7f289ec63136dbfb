#!/usr/bin/env bash
# Real GLFW windows under Xvfb: hysar-projector --window shows the projector frame (its
# screenshot must match the frame), and hysar-hmd --window shows a headset's layers.
set -euo pipefail
bin="$1"
dir=$(mktemp -d)
trap 'kill -TERM "$server" 2>/dev/null || true; rm -rf "$dir"' EXIT
(umask 077 && echo "window-test-token" > "$dir/token")
"$bin/hysar" serve --listen 127.0.0.1:0 --unix "$dir/s.sock" --token-file "$dir/token" > "$dir/serve.log" 2>&1 &
server=$!
for _ in $(seq 100); do [[ -S "$dir/s.sock" ]] && break; sleep 0.1; done
xvfb-run -a -s "-screen 0 960x600x24" "$bin/clients/hysar-projector" --connect "unix:$dir/s.sock" \
  --token-file "$dir/token" --out "$dir" --window --screenshot "$dir/shot.png"
"$bin/tests/compare_png" "$dir/shot.png" "$dir/projector_v1.png"
xvfb-run -a -s "-screen 0 1400x500x24" "$bin/clients/hysar-hmd" --connect "unix:$dir/s.sock" \
  --token-file "$dir/token" --out "$dir" --window --angles 20 --scale 0.5 --name windowed
echo "window test: projector and headset windows shown"
