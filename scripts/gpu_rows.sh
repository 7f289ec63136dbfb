#!/usr/bin/env bash
# Measures (and checks) what needs a GPU, in one run of about 5 minutes on a built tree
# (scripts/setup.sh), so that a short loan of a GPU machine is spent on it alone:
#   1. the GPU tests that compare two ways of drawing the same layers bit for bit (both eyes in
#      one pass, several headsets in one pass, packed tiles, the fill-in's pipelines), with
#      Vulkan validation on: their equality rests on the compiler, which is the GPU's here;
#   2. `hysar bench serve` with one headset per pass and with three (--headsets-per-pass),
#      multiview on, and the same with --multiview off;
#   3. BM_RecordBatch: recording a batch of 8 headsets per eye, per headset and three to a pass.
# Everything goes under OUT (tests.txt, serve-*/ and their logs, record-batch.json, gpu.txt).
# usage: scripts/gpu_rows.sh [BUILD_DIR] [OUT]
#   HEADSETS (8,32,64,128), ROW_SECONDS (5), MAX_TARGET_MIB (8192) and LEAN (a lean-baseline
#   script to run beside the rows, e.g. ../shared/perf/lean-baseline.sh) in the environment.
# Exit status: 1 when a test failed, 2 when a measurement could not be made; all of it is run.
set -uo pipefail
# Both folders as the caller named them, before moving to the repository root.
B=$(realpath -m "${1:-build}")
OUT=$(realpath -m "${2:-gpu-rows}")
[[ -n "${LEAN:-}" ]] && LEAN=$(realpath -m "$LEAN")
cd "$(dirname "$0")/.."

HEADSETS=${HEADSETS:-8,32,64,128}
SECONDS_PER_ROW=${ROW_SECONDS:-5}
MIB=${MAX_TARGET_MIB:-8192}
mkdir -p "$OUT"
status=0
step() { echo "[$(date -u +%H:%M:%S)] $*"; }

{
  date -u
  git rev-parse --short HEAD 2> /dev/null
  nvidia-smi -L 2> /dev/null || echo "nvidia-smi: none"
  "$B/hysar" --version 2>&1 | head -3
} > "$OUT/gpu.txt"

step "GPU tests (validation on) -> $OUT/tests.txt"
: > "$OUT/tests.txt"
HYSAR_VALIDATION=1 "$B/tests/hs_gpu_tests" \
  --gtest_filter='Multiview.*:SparseLayers.*:TilePacking.*:WarmUp.*' >> "$OUT/tests.txt" 2>&1 ||
  { status=1; step "a GPU test failed: see $OUT/tests.txt"; }
HYSAR_VALIDATION=1 "$B/tests/hs_projectors_gpu_tests" --gtest_filter='Fill.*' \
  >> "$OUT/tests.txt" 2>&1 || { status=1; step "a GPU test failed: see $OUT/tests.txt"; }
grep -E '^\[  (PASSED|FAILED) ' "$OUT/tests.txt"

lean=()
[[ -n "${LEAN:-}" ]] && lean=(--lean-baseline "$LEAN")
serve() {
  local name=$1
  shift
  step "hysar bench serve $* -> $OUT/serve-$name"
  "$B/hysar" bench serve --headsets "$HEADSETS" --seconds "$SECONDS_PER_ROW" \
    --max-target-mib "$MIB" ${lean[@]+"${lean[@]}"} "$@" --out "$OUT/serve-$name" \
    > "$OUT/serve-$name.log" 2>&1 || { status=2; step "failed: see $OUT/serve-$name.log"; }
}
serve per-headset --multiview on --headsets-per-pass 1
serve three-per-pass --multiview on --headsets-per-pass 3
serve per-eye --multiview off
# The rows side by side: total stereo layers/s, p99 pose-to-layer, what bound each row.
python3 - "$OUT" << 'PY' || status=2
import glob, json, os, sys
out = sys.argv[1]
for name in ("per-eye", "per-headset", "three-per-pass"):
    files = sorted(glob.glob(os.path.join(out, f"serve-{name}", "*.json")))
    if not files:
        print(f"{name}: no rows")
        continue
    for r in json.load(open(files[0])).get("rows", []):
        print(f"{name:15} {r.get('headsets'):>4} headsets  "
              f"{r.get('stereo_per_s_total', 0):8.1f} stereo/s  "
              f"p99 {r.get('latency_ms_p99') or 0:6.1f} ms  "
              f"shared {r.get('shared_pass_fraction') or 0:4.2f}  bound {r.get('bound')}")
PY

step "BM_RecordBatch -> $OUT/record-batch.json"
"$B/tests/hs_benchmarks" --benchmark_filter='BM_RecordBatch' --benchmark_repetitions=5 \
  --benchmark_report_aggregates_only=true --benchmark_out="$OUT/record-batch.json" \
  --benchmark_out_format=json > "$OUT/record-batch.txt" 2>&1 || status=2
grep -E 'median' "$OUT/record-batch.txt"
step "done (status $status)"
exit $status
