#!/usr/bin/env bash
# The clients' default --profile: devices/hololens.json under <exe_dir>/../share/hysar/configs
# (an installed tree) first, then the source tree's configs/. The binaries are copied into a
# temporary bin/ (they find libhysar-client through their build RPATH); no server is needed:
# hysar-hmd --list-devices names the profile a run would use, and hysar-loadgen reads the
# profile before it connects.
# Usage: client_default_profile.sh BUILD_DIR SOURCE_DIR
set -uo pipefail
build=$1 src=$2
dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT
fail() { echo "client_default_profile: FAIL: $*"; exit 1; }
mkdir -p "$dir/bin"
cp "$build/clients/hysar-hmd" "$build/clients/hysar-loadgen" "$dir/bin/"
share=$dir/share/hysar/configs

# No installed tree beside the binary: the source tree's profile.
out=$("$dir/bin/hysar-hmd" --list-devices 2>&1) || fail "--list-devices: $out"
[[ $out == *"will be used: $src/configs/devices/hololens.json (the default --profile)"* ]] ||
  fail "without share/: not the source tree's profile: $out"
echo "ok: without an installed tree, the source tree's configs/devices/hololens.json"

# An installed tree: its profile and its device table come first.
mkdir -p "$share/devices"
cp "$src/configs/devices/hololens.json" "$share/devices/"
out=$("$dir/bin/hysar-hmd" --list-devices 2>&1) || fail "--list-devices with share/: $out"
[[ $out == *"will be used: $share/devices/hololens.json (the default --profile)"* ]] ||
  fail "with share/: not the installed profile: $out"
[[ $out == *" of 1 profiles"* || $out == *"No USB devices listed"* ]] ||
  fail "with share/: not the installed device table (one profile): $out"
echo "ok: an installed tree's share/hysar/configs comes first"

# hysar-loadgen reads the same default, before it connects: a broken installed profile is named.
printf '{ broken' > "$share/devices/hololens.json"
out=$("$dir/bin/hysar-loadgen" --token t --connect 127.0.0.1:1 --seconds 1 2>&1); rc=$?
[[ $rc -eq 2 && $out == *"$share/devices/hololens.json"*"not valid JSON"* ]] ||
  fail "hysar-loadgen with a broken installed profile: rc $rc: $out"
echo "ok: hysar-loadgen's default profile is the installed one"
echo "3 passed, 0 failed"
