#!/usr/bin/env bash
# libhysar-client as an outside project uses it: `cmake --install` into a fresh prefix, the C
# example built from outside the source tree with nothing but the installed header, library and
# pkg-config file, then the C and the Python (ctypes) examples run against a real server and must
# each receive their layer pairs.
set -euo pipefail
bin="$1" src="$2"
dir=$(mktemp -d)
trap 'kill -TERM "${server:-}" 2>/dev/null || true; rm -rf "$dir"' EXIT
cmake --install "$bin" --prefix "$dir/prefix" --component Unspecified > "$dir/install.log"
pc=$(find "$dir/prefix" -name hysar-client.pc)
[[ -n "$pc" ]] || { echo "install: no hysar-client.pc under the prefix"; cat "$dir/install.log"; exit 1; }
export PKG_CONFIG_PATH
PKG_CONFIG_PATH=$(dirname "$pc")
libdir=$(pkg-config --variable=libdir hysar-client)
[[ -e "$libdir/libhysar-client.so.1" ]] || { echo "install: no libhysar-client.so.1 in $libdir"; exit 1; }
# Outside the tree: a copy of the example in the temp dir, compiled as C11 with warnings as errors.
mkdir "$dir/outside" && cp "$src/examples/c/hmd_example.c" "$dir/outside/"
(cd "$dir/outside" && cc -std=c11 -Wall -Wextra -Werror hmd_example.c \
  $(pkg-config --cflags --libs hysar-client) -lm -Wl,-rpath,"$libdir" -o hmd_example)
if grep -q "$src" <(pkg-config --cflags hysar-client); then
  echo "install: the pkg-config file points into the source tree"; exit 1
fi

(umask 077 && echo "install-test-token" > "$dir/token")
"$bin/hysar" serve --listen 127.0.0.1:0 --unix "$dir/s.sock" --token-file "$dir/token" > "$dir/serve.log" 2>&1 &
server=$!
for _ in $(seq 100); do [[ -S "$dir/s.sock" ]] && break; sleep 0.1; done
profile="$src/configs/devices/hololens.json"
out=$(timeout 120 "$dir/outside/hmd_example" "unix:$dir/s.sock" install-test-token "$profile" 5)
echo "$out" | tail -2
echo "$out" | grep -q "^5 layer pairs, 0 errors$" || { echo "C example: not 5 pairs"; exit 1; }
out=$(timeout 120 python3 "$src/examples/python/hmd_example.py" "unix:$dir/s.sock" \
  install-test-token "$profile" 5 --lib "$libdir/libhysar-client.so.1" --save "$dir/left.ppm")
echo "$out" | tail -2
echo "$out" | grep -q "^5 layer pairs, 0 errors$" || { echo "Python example: not 5 pairs"; exit 1; }
# The saved layer is a real picture: a PPM header and some lit pixels.
python3 - "$dir/left.ppm" <<'PY'
import sys
data = open(sys.argv[1], "rb").read()
header, _, body = data.partition(b"\n")
w, h = map(int, header.split()[1:3])
assert len(body) == w * h * 3, "PPM size"
lit = sum(1 for i in range(0, len(body), 3) if body[i] or body[i + 1] or body[i + 2])
assert 0 < lit < w * h, f"{lit} lit pixels of {w * h}"
print(f"python example: left layer {w}x{h}, {lit} lit pixels")
PY
echo "install test: the installed library serves the C and the Python example"
