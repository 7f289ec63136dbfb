#!/usr/bin/env bash
# Real GLFW windows under Xvfb. hysar-projector --window runs until stopped while the server is
# killed and started again (it must reconnect) and then changes scene (SIGHUP after an edit of
# the scene file): what its window shows at the end must be, pixel for pixel, the new scene's
# frame as the server sent it. hysar-hmd --window shows a headset's layers.
set -euo pipefail
bin="$1" src="$2"
dir=$(mktemp -d)
trap 'kill -KILL "${server:-}" "${projector:-}" 2>/dev/null || true; rm -rf "$dir"' EXIT
(umask 077 && echo "window-test-token" > "$dir/token")
cp "$src/configs/exp1-room.json" "$dir/room.json"
start_server() {
  "$bin/hysar" serve --scene "$dir/room.json" --listen 127.0.0.1:0 --unix "$dir/s.sock" \
    --token-file "$dir/token" >> "$dir/serve.log" 2>&1 &
  server=$!
  for _ in $(seq 200); do [[ -S "$dir/s.sock" ]] && return 0; sleep 0.1; done
  echo "the server did not start"; cat "$dir/serve.log"; exit 1
}
wait_for() {
  for _ in $(seq 300); do [[ -s "$1" ]] && return 0; sleep 0.1; done
  echo "no $1 within 30 s"; cat "$dir/projector.log"; exit 1
}
start_server
mkdir "$dir/p"
xvfb-run -a -s "-screen 0 960x600x24" "$bin/clients/hysar-projector" --connect "unix:$dir/s.sock" \
  --token-file "$dir/token" --out "$dir/p" --frames 0 --backoff-ms 100 --window \
  --screenshot "$dir/shot.png" > "$dir/projector.log" 2>&1 &
projector=$!
wait_for "$dir/p/projector_v1.png"
kill -KILL "$server"; wait "$server" 2>/dev/null || true
rm "$dir/p/projector_v1.png"
start_server
wait_for "$dir/p/projector_v1.png"
grep -q "reconnected" "$dir/projector.log" || { echo "no reconnect reported"; cat "$dir/projector.log"; exit 1; }
# A scene change: another material colour, reloaded by SIGHUP as version 2.
sed -i 's/"albedo": \[0.62, 0.47, 0.20\]/"albedo": [0.20, 0.47, 0.62]/' "$dir/room.json"
grep -q '"albedo": \[0.20, 0.47, 0.62\]' "$dir/room.json" || { echo "the scene edit did not apply"; exit 1; }
kill -HUP "$server"
wait_for "$dir/p/projector_v2.png"
sleep 0.5
pkill -TERM -f "^$bin/clients/hysar-projector --connect unix:$dir/s.sock"  # not xvfb-run
wait "$projector" || { echo "hysar-projector exit $?"; cat "$dir/projector.log"; exit 1; }
"$bin/tests/compare_png" "$dir/shot.png" "$dir/p/projector_v2.png"
# The two versions differ on the prop (a small part of the frame, so the peak, not the mean):
# the window shows the new scene, not the old frame.
peak=$("$bin/tests/compare_png" "$dir/p/projector_v1.png" "$dir/p/projector_v2.png" 2>&1 |
  sed -n 's/.*peak \([0-9]*\).*/\1/p' | head -1 || true)
if [[ -z "$peak" || "$peak" -lt 50 ]]; then
  echo "the scene change did not change the projector frame (peak difference '${peak}')"; exit 1
fi
xvfb-run -a -s "-screen 0 1400x500x24" "$bin/clients/hysar-hmd" --connect "unix:$dir/s.sock" \
  --token-file "$dir/token" --out "$dir" --window --angles 20 --scale 0.5 --name windowed
# With late reprojection the headset registers its display overscanned (5 degrees each side by
# default): the layers it receives, and writes, are wider and taller than the display's.
xvfb-run -a -s "-screen 0 1400x500x24" "$bin/clients/hysar-hmd" --connect "unix:$dir/s.sock" \
  --token-file "$dir/token" --out "$dir" --window --reproject --angles 20 --scale 0.5 --name warped \
  | tee "$dir/warped.log"
reprojected=$(sed -n 's/^warped: \([0-9]*\) layers reprojected.*/\1/p' "$dir/warped.log")
[[ "${reprojected:-0}" -ge 2 ]] || { echo "hysar-hmd --reproject showed no warped layer"; exit 1; }
png_size() { od -An -tu1 -j16 -N8 "$1" | awk '{print ($1*16777216+$2*65536+$3*256+$4) "x" ($5*16777216+$6*65536+$7*256+$8)}'; }
plain_pngs=("$dir"/windowed_*_left.png) wide_pngs=("$dir"/warped_*_left.png)
plain=$(png_size "${plain_pngs[0]}") wide=$(png_size "${wide_pngs[0]}")
if [[ "${plain%x*}" -ge "${wide%x*}" || "${plain#*x}" -ge "${wide#*x}" ]]; then
  echo "an overscanned layer ($wide) is not larger than the display's ($plain)"; exit 1
fi
kill -TERM "$server"; wait "$server" 2>/dev/null || true
echo "window test: the projector window showed the new scene's frame after a reconnect and a scene change; the headset window showed its layers, and overscanned ones with --reproject ($plain -> $wide)"
