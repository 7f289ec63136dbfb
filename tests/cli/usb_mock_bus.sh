#!/usr/bin/env bash
# hysar-hmd's USB options on a simulated bus (umockdev-run, which fakes sysfs, udev and
# /dev/bus/usb for libusb): tests/data/usb_mock/one_headset.umockdev holds a MOVERIO BT-300 and a
# mouse, two_headsets.umockdev adds a HoloLens 2, with the made-up ids of the fixture table
# tests/data/usb_table/. --list-devices marks the headsets, --device auto picks the one or names
# both, --watch-devices reports the one present. With the shipped table (configs/devices/): each
# public id (one file per device, VVVV_PPPP.umockdev, several make one bus) picks its profile,
# the WMR sensor hub 045e:0659 picks none, a Magic Leap and a BT-40 together are refused, and an
# entry added with --add-device is found by --device auto. Names come from an excerpt of usb.ids
# (tests/data/usb_ids/, through HYSAR_USB_IDS). Registered only where umockdev-run exists.
# Usage: usb_mock_bus.sh BUILD_DIR SOURCE_DIR
set -u
case_lib="$(cd "$(dirname "$0")" && pwd)/case_lib.sh"
build=$(cd "$1" && pwd) || exit 1
src=$(cd "$2" && pwd) || exit 1
hmd="$build/clients/hysar-hmd"
table="$src/tests/data/usb_table"
one="$src/tests/data/usb_mock/one_headset.umockdev"
two="$src/tests/data/usb_mock/two_headsets.umockdev"
mock="$src/tests/data/usb_mock"
shipped="$src/configs/devices"
export HYSAR_USB_IDS="$src/tests/data/usb_ids/usb.ids"
work="$build/tests/usb_mock_bus"
rm -rf "$work" && mkdir -p "$work"
cd "$work" || exit 1

source "$case_lib"
# check NAME WANT_RC PATTERNS BUS ARGS...: hysar-hmd ARGS on the bus BUS (one or more umockdev
# files, separated by spaces) exits WANT_RC and its stdout + stderr match every line of PATTERNS
# (grep -E, one pattern per line).
check() {
  local name="$1" want="$2" patterns="$3" bus="$4" devices=() f
  shift 4
  for f in $bus; do devices+=(-d "$f"); done
  expect "$name" "$want" all "$patterns" umockdev-run "${devices[@]}" -- "$hmd" "$@"
}
# An empty local folder, so that a /etc/hysar/devices on this machine plays no part.
mkdir -p none

check list-one 0 "^USB devices: 2$
bus 001 address 004  04b8:fe30 .*<- known headset: Epson MOVERIO BT-300 \(test id\), profile $table/moverio-bt300.json
bus 001 address 005  046d:c077  \[usb.ids: Logitech, Inc. Mouse\]$
--device auto uses the profile $table/moverio-bt300.json" \
  "$one" --list-devices --device-table "$table"
check list-two 0 "^USB devices: 3$
--device auto would refuse to choose: 2 different known headsets
Without --device auto, the configured profile will be used" \
  "$two" --list-devices --device-table "$table"
check auto-one 2 "--device auto: Epson MOVERIO BT-300 \(test id\) .* -> profile $table/moverio-bt300.json
--connect: cannot connect" \
  "$one" --device auto --device-table "$table" --token t --connect 127.0.0.1:1 --angles 0
check auto-two 2 "--device auto: 2 different known headsets are attached: Microsoft HoloLens 2 \(test id\) \(045e:fe02, bus 2 address 3, profile $table/hololens2.json\) and Epson MOVERIO BT-300 \(test id\) \(04b8:fe30, bus 1 address 4" \
  "$two" --device auto --device-table "$table" --token t --connect 127.0.0.1:1 --angles 0
check auto-shipped-table 2 "--device auto: no known headset among the 2 USB devices; using the configured profile" \
  "$one" --device auto --devices-dir none --token t --connect 127.0.0.1:1 --angles 0
check watch-present 0 "^present: Epson MOVERIO BT-300 \(test id\)  bus 001 address 004  04b8:fe30
^Watch ended: 0 arrivals and 0 departures" \
  "$one" --watch-devices 0.3 --device-table "$table"

# The shipped table: each public id alone picks its profile.
auto() { # NAME PATTERN BUS: --device auto with the shipped table on BUS
  check "$1" 2 "$2
--connect: cannot connect" "$3" --device auto --devices-dir none --token t --connect 127.0.0.1:1 --angles 0
}
auto auto-2c55-a100 "--device auto: Magic Leap One Lightpack \(ML1 Lightpack \(MLDB\)\) \(bus 001 address 006  2c55:a100\) -> profile $shipped/magicleap1.json" \
  "$mock/2c55_a100.umockdev"
auto auto-2c55-b100 "--device auto: Magic Leap One Lightpack .*2c55:b100.* -> profile $shipped/magicleap1.json" \
  "$mock/2c55_b100.umockdev"
auto auto-2c55-c001 "--device auto: Magic Leap One Control .*2c55:c001.* -> profile $shipped/magicleap1.json" \
  "$mock/2c55_c001.umockdev"
auto auto-2c55-c002 "--device auto: Magic Leap One Control .*2c55:c002.* -> profile $shipped/magicleap1.json" \
  "$mock/2c55_c002.umockdev"
auto auto-04b8-0d12 "--device auto: Epson MOVERIO BT-40 \(EPSON HMD Com&Sens: its sensors\) .*04b8:0d12.* -> profile $shipped/moverio-bt40.json" \
  "$mock/04b8_0d12.umockdev"
auto auto-04b8-0335 "--device auto: Epson MOVERIO BT-40 \(EPSON HMD Audio\) .*04b8:0335.* -> profile $shipped/moverio-bt40.json" \
  "$mock/04b8_0335.umockdev"
# The Lightpack and the Control are one headset; so are the BT-40's two functions.
auto auto-lightpack-and-control "-> profile $shipped/magicleap1.json" \
  "$mock/2c55_a100.umockdev $mock/2c55_c001.umockdev"
auto auto-bt40-both "-> profile $shipped/moverio-bt40.json" \
  "$mock/04b8_0d12.umockdev $mock/04b8_0335.umockdev"
# 045e:0659, the WMR sensor hub, is no HoloLens: nothing is picked.
auto auto-wmr-hub "--device auto: no known headset among the 1 USB devices; using the configured profile .*hololens\.json" \
  "$mock/045e_0659.umockdev"
# Two known headsets: refused, naming both (in the order libusb lists them).
check auto-magicleap-and-bt40 2 "--device auto: 2 different known headsets are attached: .* and .*; unplug all but one
Magic Leap One Lightpack \(ML1 Lightpack \(MLDB\)\) \(2c55:a100, bus 1 address 6, profile $shipped/magicleap1.json\)
Epson MOVERIO BT-40 \(EPSON HMD Com&Sens: its sensors\) \(04b8:0d12, bus 1 address 8, profile $shipped/moverio-bt40.json\)" \
  "$mock/2c55_a100.umockdev $mock/04b8_0d12.umockdev" \
  --device auto --devices-dir none --token t --connect 127.0.0.1:1 --angles 0
# --list-devices names every device from usb.ids, known or not.
check list-public 0 "^USB devices: 3$
  bus 001 address 006  2c55:a100  \[usb.ids: Magic Leap, Inc. ML1 Lightpack \(MLDB\)\]  <- known headset: Magic Leap One Lightpack \(ML1 Lightpack \(MLDB\)\), profile $shipped/magicleap1.json$
  bus 002 address 004  045e:0659  \[usb.ids: Microsoft Corp.\]$
  bus 001 address 008  04b8:0d12  \[usb.ids: Seiko Epson Corp.\]  <- known headset: Epson MOVERIO BT-40
^\(names in \[ \] from $HYSAR_USB_IDS, version 2025.07.26\)$
--device auto would refuse to choose: 2 different known headsets" \
  "$mock/2c55_a100.umockdev $mock/045e_0659.umockdev $mock/04b8_0d12.umockdev" --list-devices --devices-dir none
HYSAR_USB_IDS="$work/no-such-usb.ids" check list-without-usb-ids 0 "^  bus 002 address 004  045e:0659 *$
no usb.ids list on this machine: install the usb.ids package" \
  "$mock/045e_0659.umockdev" --list-devices --devices-dir none

# An operator adds a headset in one step; --device auto then finds it.
check before-add 2 "--device auto: no known headset among the 2 USB devices" \
  "$one" --device auto --devices-dir none --token t --connect 127.0.0.1:1 --angles 0
check add 0 "^Added 04b8:fe30 \(moverio-bt300 \(Seiko Epson Corp.\)\) -> profile moverio-bt300: $work/local/usb-04b8-fe30.json$
put this line in /etc/udev/rules.d/71-hysar-local.rules
^SUBSYSTEM==\"usb\", ENV\{DEVTYPE\}==\"usb_device\", ATTR\{idVendor\}==\"04b8\", ATTR\{idProduct\}==\"fe30\", MODE=\"0660\", TAG\+=\"uaccess\"$" \
  "$one" --add-device 04b8:fe30 --profile moverio-bt300 --devices-dir "$work/local"
check auto-after-add 2 "--device auto: moverio-bt300 \(Seiko Epson Corp.\) \(bus 001 address 004  04b8:fe30.*\) -> profile $shipped/moverio-bt300.json" \
  "$one" --device auto --devices-dir "$work/local" --token t --connect 127.0.0.1:1 --angles 0
check list-after-add 0 "04b8:fe30 .*<- known headset: moverio-bt300 \(Seiko Epson Corp.\), profile $shipped/moverio-bt300.json
--device auto uses the profile $shipped/moverio-bt300.json" \
  "$one" --list-devices --devices-dir "$work/local"
check add-again 2 "--add-device 04b8:fe30 is in the table already: '$work/local/usb-04b8-fe30.json' maps it to the profile moverio-bt300 \(remove that file to change it\)" \
  "$one" --add-device 04b8:fe30 --profile hololens --devices-dir "$work/local"

finish
