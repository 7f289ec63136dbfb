#!/usr/bin/env bash
# hysar-hmd's USB options against whatever USB bus this machine has (in CI: a container,
# usually none): --list-devices exits 0 and says which profile will be used, --watch-devices
# exits 0 or 1 with one plain line, --device auto falls back to --profile with a message, and bad
# values exit 2 naming the option. --add-device writes a local entry (into a scratch
# --devices-dir) and refuses a bad VID:PID, an unknown profile and ids the table has; a broken
# local file is an error naming it. Nothing may abort. No server, no GPU.
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

# --add-device: one step, checked.
shipped="$src/configs/devices"
check add-bad-id 2 "--add-device '04b8-0d12': expected VENDOR:PRODUCT, 1 to 4 hexadecimal digits each" \
  "$hmd" --add-device 04b8-0d12 --profile moverio-bt40 --devices-dir local
check add-id-too-long 2 "--add-device '04b8:10d12': expected VENDOR:PRODUCT" \
  "$hmd" --add-device 04b8:10d12 --profile moverio-bt40 --devices-dir local
check add-no-profile 2 "--add-device needs --profile NAME" \
  "$hmd" --add-device 1234:0001 --devices-dir local
check add-unknown-profile 2 "--profile 'no-such': not a profile of the table \(hololens, hololens2, magicleap1, moverio-bt200, moverio-bt300, moverio-bt40\)" \
  "$hmd" --add-device 1234:0001 --profile no-such --devices-dir local
check add-shipped-id 2 "--add-device 2c55:a100 is in the table already: '$shipped/magicleap1.json' maps it to the profile magicleap1$" \
  "$hmd" --add-device 2c55:a100 --profile hololens --devices-dir local
check add-and-list 2 "give --add-device or --list-devices, not both" \
  "$hmd" --add-device 1234:0001 --profile hololens --list-devices --devices-dir local
touch a-file
check add-dir-is-a-file 2 "--devices-dir '.*a-file' is not a folder" \
  "$hmd" --add-device 1234:0001 --profile hololens --devices-dir a-file
check refused-add-makes-no-folder 0 "" test ! -e local
check add-by-profile-file 0 "^Added 1234:0001 \(hololens2 \(.*\)\) -> profile hololens2: local/usb-1234-0001.json$
--device auto picks the profile $shipped/hololens2.json when the device is attached \(with --devices-dir local\)" \
  "$hmd" --add-device 1234:0001 --profile "$shipped/hololens2.json" --devices-dir local
check add-entry-written 0 '"profile": "hololens2"
"vendor_id": "0x1234"
"product_id": "0x0001"
"source": "added on site with hysar-hmd --add-device on 20[0-9-]+' cat local/usb-1234-0001.json
check add-same-id-again 2 "--add-device 1234:0001 is in the table already: 'local/usb-1234-0001.json' maps it to the profile hololens2 \(remove that file to change it\)" \
  "$hmd" --add-device 1234:0001 --profile hololens --devices-dir local
check list-with-local 0 "USB devices|No USB devices listed" "$hmd" --list-devices --devices-dir local
mkdir -p broken-local && echo '{ "profile": ' > broken-local/usb-1234-0002.json
check local-broken-list 2 "local device entries: '.*broken-local/usb-1234-0002.json': not valid JSON" \
  "$hmd" --list-devices --devices-dir broken-local
check local-broken-auto 2 "local device entries: '.*broken-local/usb-1234-0002.json': not valid JSON" \
  "$hmd" --device auto --devices-dir broken-local --token t --connect 127.0.0.1:1 --angles 0
check local-broken-add 2 "broken-local/usb-1234-0002.json': not valid JSON" \
  "$hmd" --add-device 1234:0003 --profile hololens --devices-dir broken-local
check local-missing 2 "--devices-dir '$work/nowhere' is not a folder" \
  "$hmd" --list-devices --devices-dir "$work/nowhere"
check local-without-device 2 "--devices-dir is read by --device auto, --list-devices, --watch-devices and --add-device only" \
  "$hmd" --devices-dir local --token t

finish
