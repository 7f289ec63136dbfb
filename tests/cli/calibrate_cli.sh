#!/usr/bin/env bash
# The real-installation steps of `hysar calibrate` end to end on a small device, with the
# camera replaced by the identity (each pattern file is its own capture): patterns -> decode
# -> invert -> colour -> capture, then the captured-material scene must load; optics, and
# `hysar serve --calibration` on the folder (its errors, and a calibrated start); and bad input
# must fail with a message naming it.
# Usage: calibrate_cli.sh BUILD_DIR SOURCE_DIR
set -euo pipefail
hysar="$1/hysar"
src="$2"
work="$1/tests/calibrate_cli"
rm -rf "$work" && mkdir -p "$work"
cd "$work"

"$hysar" calibrate patterns --size 64x40 --ramp 5 --grid 3 --out pat | tee patterns.log
grep -q "26 gray-code images (24 patterns, white, black) and 33 colour patches" patterns.log
"$hysar" calibrate decode --patterns pat --captures pat/gray --exposure-ms 1000 --out cal | tee decode.log
grep -q "decoded 2560 of 2560 lit camera pixels" decode.log
"$hysar" calibrate invert --calibration cal --bandwidth 0.7 | tee invert.log
grep -q "2560 device pixels estimated" invert.log
"$hysar" calibrate colour --patterns pat --captures pat/colour --exposure-ms 1000 --calibration cal --model curve | tee colour.log
grep -q "curve model from" colour.log

# A scene whose projector and headset are the 64 x 40 device.
sed -e 's/"width": 1920, "height": 1200, "fx": 3000, "fy": 3000, "cx": 959.5, "cy": 599.5/"width": 64, "height": 40, "fx": 100, "fy": 100, "cx": 31.5, "cy": 19.5/' \
    "$src/configs/exp1-room.json" > room64.json
grep -q '"width": 64' room64.json
"$hysar" calibrate capture --projector cal --hmd cal --vi pat/colour/004.png --vivd pat/colour/008.png \
    --exposure-ms 1000 --scene room64.json --out material | tee capture.log
grep -q "serve it with" capture.log
test -s material/projector.exr && test -s material/viewer.exr && test -s material/scene.json

# Bad input: a missing capture, a wrong-size capture, a missing flag.
if "$hysar" calibrate decode --patterns pat --captures nowhere --exposure-ms 1000 --out x 2> err.log; then
  echo "decode of a missing folder succeeded"; exit 1
fi
grep -q "no capture 000.png or 000.exr" err.log
"$hysar" calibrate patterns --size 32x20 --ramp 2 --grid 2 --out pat32 > /dev/null
if "$hysar" calibrate capture --projector cal --hmd cal --vi pat/colour/004.png --vivd pat32/colour/004.png \
    --exposure-ms 1000 --scene room64.json --out bad 2> err.log; then
  echo "capture with images of different sizes succeeded"; exit 1
fi
grep -q "32x20" err.log
if "$hysar" calibrate colour --patterns pat --captures pat/colour --calibration cal 2> err.log; then
  echo "colour without an exposure succeeded"; exit 1
fi
grep -q -- "--exposure-ms is required" err.log
# A calibration folder for serving: the 64 x 40 device as both projector and headset, and the
# optical constants of the 64 x 40 room.
mkdir -p calset && cp -r cal calset/projector && cp -r cal calset/hmd
"$hysar" calibrate optics --calibration calset --scene room64.json | tee optics.log
grep -q "wrote calset/optics.json: alpha 0.399" optics.log
grep -q '"kind": "hysar-optics"' calset/optics.json
serve_fails() {  # expected exit code, expected text, arguments...
  local want=$1 text=$2; shift 2
  local rc=0
  "$hysar" serve --listen 127.0.0.1:0 "$@" > serve.out 2> serve.err || rc=$?
  if [[ $rc -ne $want ]] || ! grep -qF -- "$text" serve.err; then
    echo "hysar serve $*: exit $rc (wanted $want), without \"$text\":"; cat serve.err; exit 1
  fi
}
serve_fails 1 "nowhere: no such calibration folder" --calibration nowhere --scene room64.json
serve_fails 1 "the calibrated projector (calset/projector/lut.json) is 64x40, the scene's projector" \
  --calibration calset
serve_fails 2 "--compensation applies to calibrated output" --compensation falloff
serve_fails 2 "'glare' is not falloff, albedo, hmd_alpha or black_levels" \
  --calibration calset --compensation falloff,glare --scene room64.json
cp -r calset calnan
# A NaN, as JSON writers write it (null), in the first primary.
awk '/"primaries"/ { p = 1 } p == 1 && /^ *-?[0-9]/ { sub(/-?[0-9][0-9.eE+-]*/, "null"); p = 2 } { print }' \
  calset/hmd/colour.json > calnan/hmd/colour.json
serve_fails 1 "calnan/hmd/colour.json: primaries[0][0] is null" \
  --calibration calnan --scene room64.json
cp calset/hmd/lut.json calnan/hmd/colour.json
serve_fails 1 "calnan/hmd/colour.json: not a hysar-colour file" --calibration calnan --scene room64.json
cp calset/hmd/colour.json calnan/hmd/colour.json && rm calnan/optics.json
serve_fails 1 "calnan/optics.json: missing; write the optical constants with \`hysar calibrate optics" \
  --calibration calnan --scene room64.json

# A calibrated server starts, renders the frame as drives and stops cleanly on SIGINT.
"$hysar" serve --listen 127.0.0.1:0 --calibration calset --compensation falloff,hmd_alpha \
  --scene room64.json > serve.log 2>&1 &
server=$!
for _ in $(seq 300); do grep -q "calibrated output: k" serve.log && break; sleep 0.1; done
kill -INT "$server"
wait "$server" || { echo "the calibrated server failed:"; cat serve.log; exit 1; }
grep -q "calibrated output: calibration calset: projector 64x40 (curve model), headset 64x40" serve.log
grep -q "compensation falloff, hmd_alpha; RGBA8 frames and layers carry device drive codes" serve.log
grep -q "calibrated output: k .* lit projector pixels clipped" serve.log
echo "calibrate CLI: ok"
