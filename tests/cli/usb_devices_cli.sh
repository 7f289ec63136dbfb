#!/usr/bin/env bash
# hysar-hmd's USB options against whatever USB bus this machine has (in CI: a container,
# usually none): --list-devices exits 0 and says which profile will be used, --watch-devices
# exits 0 or 1 with one plain line, --device auto falls back to --profile with a message, and bad
# values exit 2 naming the option. Nothing may abort. No server, no GPU.
# Usage: usb_devices_cli.sh BUILD_DIR SOURCE_DIR
set -u
case_lib="$(cd "$(dirname "$0")" && pwd)/case_lib.sh"
build=$(cd "$1" && pwd) || exit 1
src=$(cd "$2" && pwd) || exit 1
hmd="$build/clients/hysar-hmd"
work="$build/tests/usb_devices_cli"
rm -rf "$work" && mkdir -p "$work"
cd "$work" || exit 1

source "$case_lib"
# check NAME WANT_RC PATTERN COMMAND...: COMMAND exits WANT_RC (a list like "0|1" is allowed) and
# its stdout + stderr match PATTERN (grep -E).
check() {
  local name="$1" want="$2" pattern="$3"
  shift 3
  expect "$name" "$want" all "$pattern" "$@"
}

check list-devices 0 "^(USB devices: |No USB devices listed: )" "$hmd" --list-devices
check list-devices-says-profile 0 \
  "(the configured profile will be used: .*configs/devices/hololens\.json|--device auto uses the profile)" \
  "$hmd" --list-devices
check list-devices-with-profile 0 "moverio-bt300\.json" \
  "$hmd" --list-devices --profile "$src/configs/devices/moverio-bt300.json"
check list-devices-fixture-table 0 "USB devices|No USB devices listed" \
  "$hmd" --list-devices --device-table "$src/tests/data/usb_table"
check watch-devices "0|1" "^(Watch ended: |hysar-hmd: --watch-devices: )" \
  "$hmd" --watch-devices 0.5
check watch-devices-stops-on-sigint "0|1" "Watch ended: |hysar-hmd: --watch-devices: " \
  timeout --preserve-status -s INT 1 "$hmd" --watch-devices 0
# --device auto with a server that is not there: the profile is chosen (or kept, with a line
# saying why) before the connection fails with exit 2.
check device-auto-falls-back 2 "hysar-hmd: --device auto: .*(using the configured profile|-> profile)" \
  "$hmd" --device auto --token t --connect 127.0.0.1:1 --angles 0
check device-bad-value 2 "--device: expected one of auto, got 'usb'" \
  "$hmd" --device usb --token t
check watch-out-of-range 2 "--watch-devices: '-1' is outside \[0, 86400\]" \
  "$hmd" --watch-devices -1
check watch-nan 2 "--watch-devices: 'nan' is not a finite number" "$hmd" --watch-devices nan
check list-and-watch 2 "give --list-devices or --watch-devices, not both" \
  "$hmd" --list-devices --watch-devices 1
check table-missing 2 "--device-table '$work/none' is not a folder" \
  "$hmd" --list-devices --device-table "$work/none"
mkdir -p broken && echo '{ "name": "x", "usb": [ { "vendor_id": "04b8", "product_id": "0x1" } ] }' > broken/x.json
check table-broken 2 "--device-table '.*broken/x\.json': usb\[0\]\.vendor_id" \
  "$hmd" --list-devices --device-table "$work/broken"
check table-without-device 2 "--device-table is read by --device auto" \
  "$hmd" --device-table "$src/configs/devices" --token t
check profile-broken 2 "--profile '$work/none.json'" \
  "$hmd" --list-devices --profile "$work/none.json"

finish
