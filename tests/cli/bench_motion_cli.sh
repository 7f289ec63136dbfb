#!/usr/bin/env bash
# `hysar bench motion --quick`: checks that the command works end to end, never an accuracy or a
# speed. One short trace in two modes: the JSON has the documented keys with finite values,
# layers were shown and compared, the plot is written; bad flags exit 2 with one line naming them.
set -euo pipefail
hysar="$1/hysar"
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
command -v python3 > /dev/null || { echo "python3 is needed to read the JSON"; exit 1; }

if ! "$hysar" bench motion --quick --traces turn --modes none,both --seconds 1.5 \
        --reference-frames 6 --scale 0.25 --delay-ms 5 --json "$out/motion.json" \
        --plot "$out/motion.png" \
        > "$out/table.txt" 2> "$out/progress.txt"; then
    cat "$out/progress.txt" "$out/table.txt"
    exit 1
fi
python3 - "$out/motion.json" <<'PY'
import json, math, sys
j = json.load(open(sys.argv[1]))
assert sorted(j["traces"]) == ["turn"], j["traces"].keys()
modes = j["traces"]["turn"]
assert sorted(modes) == ["both", "none"], modes.keys()
for name, r in modes.items():
    for k in ("p50_px", "p95_px", "max_px", "m2p_p50_ms", "m2p_p95_ms", "client_ms"):
        assert isinstance(r[k], (int, float)) and math.isfinite(r[k]) and r[k] >= 0, (name, k, r)
    assert r["p50_px"] <= r["p95_px"] <= r["max_px"], (name, r)
    assert r["frames"] > 0 and r["m2p_p50_ms"] > 0, (name, r)
# With reprojection the layer is served overscanned (5 degrees each side by default).
assert j["overscan_deg"] == 5, j["overscan_deg"]
plain, wide = modes["none"]["served_eye"], modes["both"]["served_eye"]
assert wide[0] > plain[0] and wide[1] > plain[1], (plain, wide)
assert plain == j["served_eye"], (plain, j["served_eye"])
# The tracker measures its velocities by default, and the JSON says with what noise.
t = j["tracker"]
assert t["velocity"] is True and t["velocity_noise_dps"] > 0 and t["noise_deg"] > 0, t
print("bench motion: JSON as documented")
PY
grep -q '^turn' "$out/table.txt" || { cat "$out/table.txt"; exit 1; }

# A tracker of poses alone (--poses-only): served, and the JSON says so.
if ! "$hysar" bench motion --quick --poses-only --traces walk --modes predict --seconds 1 \
        --reference-frames 3 --scale 0.25 --json "$out/poses.json" > /dev/null 2> "$out/p.txt"; then
    cat "$out/p.txt"
    exit 1
fi
python3 - "$out/poses.json" <<'PY'
import json, sys
j = json.load(open(sys.argv[1]))
assert j["tracker"]["velocity"] is False and j["tracker"]["velocity_noise_dps"] == 0, j["tracker"]
assert j["traces"]["walk"]["predict"]["frames"] > 0, j["traces"]
PY
[[ -s "$out/motion.png" && -s "$out/motion.svg" ]] || { echo "no plot written"; exit 1; }

for bad in "--traces run" "--modes fast" "--seconds 0" "--delay-ms -1" "--scale 2" \
        "--overscan-deg 31" "--plane-nearer-m 2" "--plane-nearer-m nan" \
        "--velocity-noise-dps -1" "--velocity-noise-mm-s nan" \
        "--poses-only --velocity-noise-dps 1" "--frobnicate"; do
    set +e
    # shellcheck disable=SC2086
    "$hysar" bench motion $bad > "$out/o.txt" 2> "$out/e.txt"
    rc=$?
    set -e
    if [[ $rc -ne 2 ]]; then echo "bench motion $bad: exit $rc, expected 2"; cat "$out/e.txt"; exit 1; fi
    flag=${bad%% *}
    grep -q -- "$flag" "$out/e.txt" || { echo "bench motion $bad: the error does not name $flag"; cat "$out/e.txt"; exit 1; }
done
"$hysar" bench motion --help | grep -q 'Example: hysar bench motion'
echo "bench motion: ok"
