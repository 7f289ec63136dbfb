#!/usr/bin/env bash
# hysar-hmd's USB options on a simulated bus (umockdev-run, which fakes sysfs, udev and
# /dev/bus/usb for libusb): tests/data/usb_mock/one_headset.umockdev holds a MOVERIO BT-300 and a
# mouse, two_headsets.umockdev adds a HoloLens 2, with the made-up ids of the fixture table
# tests/data/usb_table/. --list-devices marks the headsets, --device auto picks the one or names
# both, --watch-devices reports the one present. Registered only where umockdev-run exists.
# Usage: usb_mock_bus.sh BUILD_DIR SOURCE_DIR
set -u
case_lib="$(cd "$(dirname "$0")" && pwd)/case_lib.sh"
build=$(cd "$1" && pwd) || exit 1
src=$(cd "$2" && pwd) || exit 1
hmd="$build/clients/hysar-hmd"
table="$src/tests/data/usb_table"
one="$src/tests/data/usb_mock/one_headset.umockdev"
two="$src/tests/data/usb_mock/two_headsets.umockdev"
work="$build/tests/usb_mock_bus"
rm -rf "$work" && mkdir -p "$work"
cd "$work" || exit 1

source "$case_lib"
# check NAME WANT_RC PATTERNS BUS ARGS...: hysar-hmd ARGS on the bus BUS exits WANT_RC and its
# stdout + stderr match every line of PATTERNS (grep -E, one pattern per line).
check() {
  local name="$1" want="$2" patterns="$3" bus="$4"
  shift 4
  expect "$name" "$want" all "$patterns" umockdev-run -d "$bus" -- "$hmd" "$@"
}

check list-one 0 "^USB devices: 2$
bus 001 address 004  04b8:fe30 .*<- known headset: Epson MOVERIO BT-300 \(test id\), profile $table/moverio-bt300.json
bus 001 address 005  046d:c077 *$
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
  "$one" --device auto --token t --connect 127.0.0.1:1 --angles 0
check watch-present 0 "^present: Epson MOVERIO BT-300 \(test id\)  bus 001 address 004  04b8:fe30
^Watch ended: 0 arrivals and 0 departures" \
  "$one" --watch-devices 0.3 --device-table "$table"

finish
