#!/usr/bin/env bash
# Every numeric flag has a range (docs/LIMITS.md) checked as the flags are read: a value outside
# it, NaN, infinity, 1e300 and trailing characters must each end the command with exit status 2
# and one message that names the flag, the value and the range, before any work (no device, no
# file written), so nothing here needs a GPU. A few values inside the ranges are accepted.
# Usage: numeric_ranges.sh BUILD_DIR
set -u
case_lib="$(cd "$(dirname "$0")" && pwd)/case_lib.sh"
build=$(cd "$1" && pwd) || exit 1
hysar="$build/hysar"
work="$build/tests/numeric_ranges"
rm -rf "$work" && mkdir -p "$work"
cd "$work" || exit 1

source "$case_lib"
# refused FLAG VALUE RANGE COMMAND...: COMMAND exits 2 and its stderr holds "FLAG: 'VALUE'" and
# RANGE (fixed strings). The time limit guards against a value that is wrongly accepted and
# starts the work.
refused() {
  local flag="$1" value="$2" range="$3"
  shift 3
  CASE_GREP=-F expect "$flag '$value'" 2 err "$flag: '$value'"$'\n'"$range" "$@"
}
# accepted COMMAND...: COMMAND exits 0.
accepted() { CASE_TIMEOUT=120 expect "accepted" 0 all "" "$@"; }

# Values every real-number flag must refuse, whatever its range.
not_numbers=(nan NaN inf -inf 1e300 1e999 12abc 0x10 " 1" "")

# hysar render
R=(render --out "$work/render" --no-reference)
for v in "${not_numbers[@]}" 0 -1 2e6; do
  refused --white "$v" "[1e-06, 1e+06]" "$hysar" "${R[@]}" --white "$v"
done
refused --angles 720 "[-360, 360]" "$hysar" "${R[@]}" --angles 0,720
refused --angles nan "[-360, 360]" "$hysar" "${R[@]}" --angles nan
refused --angles 1e300 "[-360, 360]" "$hysar" "${R[@]}" --angles 1e300
refused --heights 1e5 "[-10000, 10000]" "$hysar" "${R[@]}" --heights M,1e5
refused --heights inf "[-10000, 10000]" "$hysar" "${R[@]}" --heights inf
refused --heights 1.5m "[-10000, 10000]" "$hysar" "${R[@]}" --heights 1.5m
[ ! -e "$work/render" ] || { failures=$((failures + 1)); echo "FAIL render wrote $work/render"; }

# hysar serve (exit 2 before the scene, the token or the device)
S=(serve --token-file "$work/no-such-token")
refused --listen 127.0.0.1:80abc "[0, 65535]" "$hysar" "${S[@]}" --listen 127.0.0.1:80abc
refused --listen 127.0.0.1:70000 "[0, 65535]" "$hysar" "${S[@]}" --listen 127.0.0.1:70000
refused --listen 127.0.0.1:-1 "[0, 65535]" "$hysar" "${S[@]}" --listen 127.0.0.1:-1
refused --listen 127.0.0.1 "[0, 65535]" "$hysar" "${S[@]}" --listen 127.0.0.1
refused --admin-listen 70000 "[0, 65535]" "$hysar" "${S[@]}" --admin-listen 70000
refused --admin-listen 127.0.0.1:9100x "[0, 65535]" "$hysar" "${S[@]}" --admin-listen 127.0.0.1:9100x
refused --admin-listen 127.0.0.1:-1 "[0, 65535]" "$hysar" "${S[@]}" --admin-listen 127.0.0.1:-1
refused --admin-listen nan "[0, 65535]" "$hysar" "${S[@]}" --admin-listen nan
refused --max-sessions 0 "[1, 65536]" "$hysar" "${S[@]}" --max-sessions 0
refused --max-sessions 1e3 "[1, 65536]" "$hysar" "${S[@]}" --max-sessions 1e3
refused --max-pending nan "[1, 65536]" "$hysar" "${S[@]}" --max-pending nan
refused --idle-timeout-ms inf "[0, 86400000]" "$hysar" "${S[@]}" --idle-timeout-ms inf
refused --frame-timeout-ms 5 "[10, 86400000]" "$hysar" "${S[@]}" --frame-timeout-ms 5
refused --max-eye-pixels 1e300 "[1, 67108864]" "$hysar" "${S[@]}" --max-eye-pixels 1e300
refused --max-viewer-hz 1.5 "[0, 1000]" "$hysar" "${S[@]}" --max-viewer-hz 1.5
refused --encoder-threads 65 "[0, 64]" "$hysar" "${S[@]}" --encoder-threads 65
refused --planning-threads 65 "[0, 64]" "$hysar" "${S[@]}" --planning-threads 65
refused --headsets-per-pass 0 "[1, 4]" "$hysar" "${S[@]}" --headsets-per-pass 0
refused --headsets-per-pass 5 "[1, 4]" "$hysar" "${S[@]}" --headsets-per-pass 5
refused --agent-port 0 "[1, 65535]" "$hysar" "${S[@]}" --agent-port 0
refused --agent-port 1e3 "[1, 65535]" "$hysar" "${S[@]}" --agent-port 1e3
refused --headset-mbps -1 "[0, 100000]" "$hysar" "${S[@]}" --headset-mbps -1
refused --headset-mbps 3M "[0, 100000]" "$hysar" "${S[@]}" --headset-mbps 3M
refused --room-mbps 1e6 "[0, 100000]" "$hysar" "${S[@]}" --room-mbps 1e6
refused --room-mbps 0.05 "below 0.1 Mbit/s" "$hysar" "${S[@]}" --room-mbps 0.05
# The word flags beside them: one of their words, the same exit before any work.
CASE_GREP=-F expect "--pack-tiles maybe" 2 err "--pack-tiles: expected auto, on or off, got 'maybe'" \
  "$hysar" "${S[@]}" --pack-tiles maybe
CASE_GREP=-F expect "--multiview both" 2 err "--multiview: expected auto, on or off, got 'both'" \
  "$hysar" "${S[@]}" --multiview both

# hysar cluster config
refused --agent-port 70000 "[1, 65535]" "$hysar" cluster config --node a=h:1 --agent-port 70000
refused --max-triangles 99999999999999999999 "[2, 4294967296]" "$hysar" "${S[@]}" --max-triangles 99999999999999999999

# hysar bench serve, encoding, accuracy
refused --seconds 1e300 "[0.1, 3600]" "$hysar" bench serve --seconds 1e300
refused --seconds nan "[0.1, 3600]" "$hysar" bench serve --seconds nan
refused --seconds 5s "[0.1, 3600]" "$hysar" bench serve --seconds 5s
refused --headsets 0 "[1, 256]" "$hysar" bench serve --headsets 1,0
refused --headsets "" "[1, 256]" "$hysar" bench serve --headsets 1,,2
refused --frames 1.5 "[1, 10000]" "$hysar" bench serve --frames 1.5
refused --headset-mbps nan "[0, 100000]" "$hysar" bench serve --headset-mbps nan
refused --room-mbps 0.01 "below 0.1 Mbit/s" "$hysar" bench serve --room-mbps 0.01
refused --layer-quality 101 "[1, 100]" "$hysar" bench serve --layer-quality 101
refused --lp-threads 999 "[1, 256]" "$hysar" bench serve --lp-threads 1,999
refused --repeats 0 "[1, 1000]" "$hysar" bench accuracy --repeats 0 --out "$work/acc"
refused --repeats 1e3 "[1, 1000]" "$hysar" bench accuracy --repeats 1e3 --out "$work/acc"
refused --repeats inf "[1, 1000]" "$hysar" bench encoding --repeats inf
refused --repeats 7x "[1, 1000]" "$hysar" bench encoding --repeats 7x
[ ! -e "$work/acc" ] || { failures=$((failures + 1)); echo "FAIL bench accuracy wrote $work/acc"; }

# hysar eval compare (the range is checked before the missing images are)
for v in nan inf 1e300 20x 256 -1; do
  refused --threshold "$v" "[0, 255]" "$hysar" eval compare --threshold "$v"
done
for v in nan 361 -1 2.5; do
  refused --around "$v" "[0, 360]" "$hysar" eval report --around "$v" --out "$work/rep"
done
[ ! -e "$work/rep" ] || { failures=$((failures + 1)); echo "FAIL eval report wrote $work/rep"; }

# hysar calibrate
refused --size 1x10 "[2, 16384]" "$hysar" calibrate patterns --size 1x10 --out "$work/pat"
refused --size 20000x10 "[2, 16384]" "$hysar" calibrate patterns --size 20000x10 --out "$work/pat"
refused --size 32x "[2, 16384]" "$hysar" calibrate patterns --size 32x --out "$work/pat"
refused --size 32x20x "[2, 16384]" "$hysar" calibrate patterns --size 32x20x --out "$work/pat"
refused --size -32x20 "[2, 16384]" "$hysar" calibrate patterns --size -32x20 --out "$work/pat"
refused --ramp 1 "[2, 256]" "$hysar" calibrate patterns --size 8x8 --ramp 1 --out "$work/pat"
refused --ramp 2.5 "[2, 256]" "$hysar" calibrate patterns --size 8x8 --ramp 2.5 --out "$work/pat"
refused --grid nan "[2, 16]" "$hysar" calibrate patterns --size 8x8 --grid nan --out "$work/pat"
refused --grid 17 "[2, 16]" "$hysar" calibrate patterns --size 8x8 --grid 17 --out "$work/pat"
[ ! -e "$work/pat" ] || { failures=$((failures + 1)); echo "FAIL calibrate patterns wrote $work/pat"; }
D=(calibrate decode --patterns "$work/none" --captures "$work/none" --out "$work/dec")
for v in "${not_numbers[@]}" 0 -5 7e4; do
  refused --exposure-ms "$v" "[0.001, 60000]" "$hysar" "${D[@]}" --exposure-ms "$v"
done
refused --black-threshold -1 "[0, 65535]" "$hysar" "${D[@]}" --exposure-ms 10 --black-threshold -1
refused --white-threshold nan "[0, 65535]" "$hysar" "${D[@]}" --exposure-ms 10 --white-threshold nan
refused --bandwidth -1 "[0, 64]" "$hysar" calibrate invert --calibration "$work/none" --bandwidth -1
refused --bandwidth 1e300 "[0, 64]" "$hysar" calibrate invert --calibration "$work/none" --bandwidth 1e300
refused --max-gap 0 "[0.01, 64]" "$hysar" calibrate invert --calibration "$work/none" --max-gap 0
refused --exposure-ms inf "[0.001, 60000]" "$hysar" calibrate colour --patterns "$work/none" \
  --captures "$work/none" --calibration "$work/none" --exposure-ms inf
C=(calibrate capture --projector "$work/none" --hmd "$work/none" --vi a.png --vivd b.png --out "$work/cap")
refused --noise-floor -1 "[0, 65535]" "$hysar" "${C[@]}" --exposure-ms 10 --noise-floor -1
refused --angle 400 "[-360, 360]" "$hysar" "${C[@]}" --exposure-ms 10 --angle 400
refused --exposure-ms 1e300 "[0.001, 60000]" "$hysar" "${C[@]}" --exposure-ms 1e300
refused --scale 0 "[0.05, 4]" "$hysar" calibrate simulate --scale 0
refused --scale nan "[0.05, 4]" "$hysar" calibrate simulate --scale nan
refused --scale 5 "[0.05, 4]" "$hysar" calibrate simulate --scale 5
refused --noise -0.1 "[0, 255]" "$hysar" calibrate simulate --noise -0.1
refused --noise inf "[0, 255]" "$hysar" calibrate simulate --noise inf
refused --angle 1e300 "[-360, 360]" "$hysar" calibrate simulate --angle 1e300
refused --bandwidth abc "[0, 64]" "$hysar" calibrate simulate --bandwidth abc

# The clients (their full set of bad arguments: clients_bad_args.sh)
T=(--token x --connect 127.0.0.1:1)
refused --scale 1e300 "[0.01, 8]" "$build/clients/hysar-hmd" "${T[@]}" --scale 1e300
refused --scale nan "[0.01, 8]" "$build/clients/hysar-hmd" "${T[@]}" --scale nan
refused --frames 1e3 "[0, 1000000000]" "$build/clients/hysar-projector" "${T[@]}" --frames 1e3
refused --rate inf "[0.1, 1000]" "$build/clients/hysar-loadgen" "${T[@]}" --rate inf
refused --viewers 12abc "[1, 1024]" "$build/clients/hysar-loadgen" "${T[@]}" --viewers 12abc
refused --retries -2 "[-1, 1000000]" "$build/clients/hysar-projector" "${T[@]}" --retries -2
refused --backoff-ms 0 "[1, 60000]" "$build/clients/hysar-hmd" "${T[@]}" --backoff-ms 0
refused --clear-after-ms 1e9 "[1, 600000]" "$build/clients/hysar-hmd" "${T[@]}" --window --clear-after-ms 1e9
refused --overscan-deg 31 "[0, 30]" "$build/clients/hysar-hmd" "${T[@]}" --window --reproject --overscan-deg 31
refused --overscan-deg nan "[0, 30]" "$build/clients/hysar-hmd" "${T[@]}" --window --reproject --overscan-deg nan
refused --seconds -1 "[0, 86400]" "$build/clients/hysar-loadgen" "${T[@]}" --seconds -1

# Values inside the ranges: a leading '+', the bounds themselves (a small device, no GPU).
accepted "$hysar" calibrate patterns --size 2x16384 --ramp +2 --grid 2 --out "$work/pat_ok"
accepted "$hysar" calibrate patterns --size 8x8 --ramp 256 --grid 16 --out "$work/pat_ok2"

finish
