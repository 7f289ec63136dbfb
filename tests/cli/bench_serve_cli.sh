#!/usr/bin/env bash
# `hysar bench serve --quick`: checks that the command works end to end, never a speed. The
# JSON has both baselines and every served row (the default and an LP_NUM_THREADS=1 child) with
# stereo layers received and finite latencies; the lean-baseline command's figures are parsed
# (a stand-in command: the project does not depend on the real script); the PNG exists; a bad
# flag exits 2 with one line naming it.
set -euo pipefail
hysar="$1/hysar"
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
command -v python3 > /dev/null || { echo "python3 is needed to read the JSON"; exit 1; }

if ! "$hysar" bench serve --quick --out "$out/bs" --lp-threads 1 --encoder-threads 2 \
        --max-batch-viewers 4 \
        --lean-baseline 'echo lean_stereo_ms=40.00 lean_stereo_per_s=25.0 seg=64x32' \
        > "$out/table.txt" 2> "$out/progress.txt"; then
    cat "$out/progress.txt" "$out/table.txt"
    exit 1
fi
python3 - "$out/bs/bench-serve.json" <<'PY'
import json, math, sys
j = json.load(open(sys.argv[1]))
def finite(x):
    return isinstance(x, (int, float)) and math.isfinite(x)
names = [b["name"] for b in j["baselines"]]
assert names == ["full frame", "lean"], names
for b in j["baselines"]:
    assert finite(b["stereo_per_s"]) and b["stereo_per_s"] > 0, b
    assert b["triangles"] > 0, b
assert j["baselines"][0]["triangles"] > j["baselines"][1]["triangles"], j["baselines"]
assert j["lean_script"]["ok"] and j["lean_script"]["stereo_per_s"] == 25.0, j["lean_script"]
rows = j["rows"]
got = sorted((r["headsets"], r["lp_num_threads"] or 0) for r in rows)
assert got == [(1, 0), (1, 1), (2, 0), (2, 1)], got
for r in rows:
    assert r["stereo_layers"] > 0, r
    assert r["errors"] == 0, r  # a headset that errs stops sending poses: its row is wrong
    assert finite(r["latency_ms_p50"]) and finite(r["latency_ms_p99"]), r
    assert r["latency_ms_p50"] <= r["latency_ms_p99"], r
    assert finite(r["first_layer_ms_p50"]) and r["first_layer_ms_p50"] <= r["first_layer_ms_max"], r
    assert finite(r["stereo_per_s_total"]) and r["stereo_per_s_total"] > 0, r
    assert finite(r["render_thread_busy"]) and 0 < r["render_thread_busy"] <= 1.05, r
    assert finite(r["stage_ms_mean"]["device"]) and r["stage_ms_mean"]["device"] > 0, r
    # Pacing and where the limit is (every row of a served bench has both).
    assert finite(r["interval_ms_p50"]) and r["interval_ms_p50"] <= r["interval_ms_p99"], r
    for k in ("render_thread", "gpu", "encoders", "cores"):
        assert finite(r["busy"][k]) and 0 <= r["busy"][k] <= 1.5, (k, r["busy"])
    assert r["bound"] in ("poses", "sockets", "render_thread", "gpu", "encoders", "cores",
                          "latency"), r["bound"]
    assert r["bound_why"], r
    for k in ("served_over_full", "served_over_lean", "served_over_lean_script"):
        assert finite(r[k]) and r[k] > 0, (k, r)
c = j["config"]
assert c["encoder_threads"] == 2 and c["max_batch_viewers"] == 4, c
m = j["machine"]
assert m["vulkan_device"] and m["cores"] >= 1 and m["date"], m
print("bench serve: %d rows, JSON as documented" % len(rows))
PY
[[ $(head -c 8 "$out/bs/bench-serve.png" | od -An -tx1 | tr -d ' \n') == 89504e470d0a1a0a ]]
python3 "$(dirname "$0")/check_figure_svg.py" "$out/bs/bench-serve.svg" --plots 1
grep -q '^served ' "$out/table.txt"
grep -q '^lean script ' "$out/table.txt"
[[ $(grep -c 'headset(s):' "$out/progress.txt") -eq 4 ]]

# Lossy tiles (encoding 3): served, and fewer bytes per layer than the lossless tiles above.
"$hysar" bench serve --quick --headsets 1 --encoding lossy --out "$out/lossy" > /dev/null 2>&1 ||
    { echo "bench serve --encoding lossy failed"; exit 1; }
python3 - "$out/bs/bench-serve.json" "$out/lossy/bench-serve.json" <<'PY'
import json, sys
tiles = json.load(open(sys.argv[1]))
lossy = json.load(open(sys.argv[2]))
assert lossy["config"]["encoding"] == "lossy", lossy["config"]
t = [r["bytes_per_layer"] for r in tiles["rows"] if r["headsets"] == 1 and not r["lp_num_threads"]][0]
l = lossy["rows"][0]
assert l["stereo_layers"] > 0 and l["errors"] == 0, l
assert l["bytes_per_layer"] < 0.5 * t, (l["bytes_per_layer"], t)
print("bench serve: lossy %.0f bytes per layer against %.0f for tiles" % (l["bytes_per_layer"], t))
PY

# Overscan: the headsets register a wider display (as hysar-hmd --reproject does) and are served.
"$hysar" bench serve --quick --headsets 1 --overscan-deg 5 --out "$out/wide" > /dev/null 2>&1 ||
    { echo "bench serve --overscan-deg failed"; exit 1; }
python3 - "$out/bs/bench-serve.json" "$out/wide/bench-serve.json" <<'PY'
import json, sys
plain = json.load(open(sys.argv[1]))["config"]
wide = json.load(open(sys.argv[2]))
c = wide["config"]
assert c["overscan_deg"] == 5 and plain["overscan_deg"] == 0, (c, plain)
assert plain["served_eye"] == [plain["eye_width"], plain["eye_height"]], plain
assert c["served_eye"][0] > c["eye_width"] and c["served_eye"][1] > c["eye_height"], c
r = wide["rows"][0]
assert r["stereo_layers"] > 0 and r["errors"] == 0, r
print("bench serve: overscanned %s per eye served" % c["served_eye"])
PY
"$hysar" bench serve --overscan-deg 31 > /dev/null 2> "$out/e.txt" && { echo "--overscan-deg 31 accepted"; exit 1; }
grep -q -- "--overscan-deg" "$out/e.txt" || { echo "the error does not name --overscan-deg"; cat "$out/e.txt"; exit 1; }

# Under a bit-rate limit far below what the lossy headset takes, its quality is lowered within
# the row, and the row says so.
"$hysar" bench serve --quick --headsets 1 --encoding lossy --headset-mbps 0.3 \
    --out "$out/limited" > /dev/null 2>&1 || { echo "bench serve --headset-mbps failed"; exit 1; }
python3 - "$out/limited/bench-serve.json" <<'PY'
import json, sys
j = json.load(open(sys.argv[1]))
assert j["config"]["headset_mbps"] == 0.3 and j["config"]["room_mbps"] == 0, j["config"]
r = j["rows"][0]
assert r["stereo_layers"] > 0 and r["errors"] == 0, r
assert r["mbps_per_headset"] > 0, r
assert 0 < r["layer_quality_mean"] < 90, r
print("bench serve: under 0.3 Mbit/s, %.2f Mbit/s at quality %.0f, %.1f Hz" %
      (r["mbps_per_headset"], r["layer_quality_mean"], r["rate_limit_hz_mean"]))
PY

# A bad flag: exit 2 and one line that names it.
bad() {
    local flag=$1; shift
    local rc=0
    "$hysar" bench serve "$@" > /dev/null 2> "$out/err.txt" || rc=$?
    [[ $rc -eq 2 ]] || { echo "bench serve $*: exit $rc, not 2"; exit 1; }
    [[ $(wc -l < "$out/err.txt") -eq 1 ]] || { echo "bench serve $*: not one line:"; cat "$out/err.txt"; exit 1; }
    grep -q -- "$flag" "$out/err.txt" || { echo "bench serve $*: does not name $flag:"; cat "$out/err.txt"; exit 1; }
}
bad --headsets --headsets 0
bad --headsets --headsets 1,,2
bad --seconds --seconds -1
bad --seconds --seconds
bad --format --format png
bad --encoding --encoding zip
bad --pack-tiles --pack-tiles maybe
bad --multiview --multiview both
bad --headsets-per-pass --headsets-per-pass 0
bad --headsets-per-pass --headsets-per-pass 9
bad --lp-threads --lp-threads x
bad --encoder-threads --encoder-threads 65
bad --max-batch-viewers --max-batch-viewers 1025
bad --planning-threads --planning-threads 65
bad --max-target-mib --max-target-mib 0
bad --headset-mbps --headset-mbps 0.05
bad --room-mbps --room-mbps x
bad --bogus --bogus
bad --profile --profile no-such-headset --quick
echo "bench serve: files, rows and errors as documented"
