#!/usr/bin/env bash
# Set-up, then the main job on the embedded default scene (the paper's experiment-1 room):
#  1. hysar serve on loopback (it compiles and exercises its pipelines before it listens to a
#     headset: the warm-up, its cost in serve.log; the pipeline cache in out/state/ makes the
#     next start faster); one projector client and five headsets at -40, -20, 0, 20 and 40 deg,
#     ten layer pairs each, receive their frames and layers into out/serve/, with a summary
#     that shows each headset's first layer apart from its steady ones; clean shutdown;
#  2. hysar render: the offline Fig. 7 contact sheet and the error against the reference.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh
out=out/serve
rm -rf "$out" && mkdir -p "$out"
(umask 077 && head -c 16 /dev/urandom | od -An -tx1 | tr -d ' \n' > "$out/token")
./build/hysar serve --listen 127.0.0.1:0 --unix "$out/hysar.sock" --token-file "$out/token" \
  --stats-file "$out/server_stats.json" --pipeline-cache out/state/pipelines.bin \
  > "$out/serve.log" 2>&1 &
server=$!
trap 'kill -TERM $server 2>/dev/null || true' EXIT
for _ in $(seq 600); do [[ -S "$out/hysar.sock" ]] && break; sleep 0.1; done
[[ -S "$out/hysar.sock" ]] || { echo "demo: the server did not start"; cat "$out/serve.log"; exit 1; }
addr="unix:$out/hysar.sock"

./build/clients/hysar-projector --connect "$addr" --token-file "$out/token" --out "$out/projector"
for a in -40 -20 0 20 40; do
  ./build/clients/hysar-hmd --connect "$addr" --token-file "$out/token" --angles "$a" --name "hmd_${a}deg" \
    --frames 10 --out "$out/hmd" --summary "$out/hmd_${a}deg.json" &
done
wait $(jobs -p | grep -v "^$server$") 2>/dev/null || true
kill -TERM "$server"
wait "$server"
trap - EXIT

python3 - "$out" <<'PY' 2>/dev/null || cat "$out"/hmd_*.json
import json, sys, glob, os
out = sys.argv[1]
print(f"\n{'viewer':<14}{'frames':>8}{'first layer ms':>16}{'steady p50 ms':>15}{'MB':>8}")
num = lambda v, w: f"{v:>{w}.1f}" if v is not None else f"{'-':>{w}}"
for f in sorted(glob.glob(os.path.join(out, "hmd_*.json")), key=lambda p: int(p.split('_')[-1][:-8])):
    j = json.load(open(f))
    print(f"{j['name']:<14}{j['frames']:>8}{num(j.get('first_layer_ms'), 16)}"
          f"{num(j.get('steady_latency_ms_p50'), 15)}{j['bytes']/1e6:>8.1f}")
s = json.load(open(os.path.join(out, "server_stats.json")))
print(f"projector renders: {s['projector_renders']}  (mean VD pass {s['timing_ms']['vd_pass_mean']:.1f} ms, encode {s['timing_ms']['vd_encode_mean']:.1f} ms per layer)")
print("first layer: a new headset's first layer pair, from its pose to its second eye; steady:"
      " the median of the others")
PY
grep -h "warm-up:" "$out/serve.log" || true
echo "demo: projector frame and headset layers in $out/; server log $out/serve.log"

./build/hysar render --out out/render "$@"
echo "demo: open out/render/sheet.png (Fig. 7 layout); figures in out/render/render.json"
