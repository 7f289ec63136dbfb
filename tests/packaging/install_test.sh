#!/usr/bin/env bash
# `cmake --install` into a fresh prefix, as a host installs the server: every file the docs
# promise is in place, the installed binaries run from outside the source and build trees
# (`hysar --help`, `hysar render` on the embedded scene, the clients' --help), the installed
# systemd unit names the installed binary and passes `systemd-analyze verify` without a single
# warning, and the Containerfile's build stage installs every library the build needs.
set -euo pipefail
bin="$1" src="$2"
dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT
prefix="$dir/prefix"
fail() { echo "install test: $*" >&2; exit 1; }

cmake --install "$bin" --prefix "$prefix" > "$dir/install.log" || { cat "$dir/install.log"; fail "cmake --install failed"; }
for f in bin/hysar bin/hysar-hmd bin/hysar-projector bin/hysar-loadgen \
         lib/libhysar-client.so.1 lib/pkgconfig/hysar-client.pc include/hysar_client.h \
         share/hysar/configs/exp1-room.json share/hysar/configs/devices/hololens.json \
         share/hysar/hysar.env.example lib/systemd/system/hysar.service \
         lib/udev/rules.d/70-hysar-headsets.rules \
         share/doc/hysar/README.md share/doc/hysar/LICENSE share/doc/hysar/CITATION.cff \
         share/doc/hysar/docs/OPERATIONS.md share/doc/hysar/protocol/PROTOCOL.md \
         share/doc/hysar/examples/c/hmd_example.c; do
  [[ -e "$prefix/$f" ]] || fail "$f is not installed"
done
# No installed program or library looks for its libraries in the trees it came from.
for f in "$prefix"/bin/* "$prefix"/lib/*.so.1; do
  rpath=$(readelf -d "$f" | grep -E "RUNPATH|RPATH" || true)
  if [[ "$rpath" == *"$src"* || "$rpath" == *"$bin"* ]]; then fail "$f: $rpath names the source or build tree"; fi
done
# No installed text file points back into the trees it came from.
if grep -rlI -e "$src" -e "$bin" "$prefix/bin" "$prefix/lib" "$prefix/share/hysar" 2>/dev/null | grep -q .; then
  fail "installed files name the source or build tree: $(grep -rlI -e "$src" -e "$bin" "$prefix/bin" "$prefix/lib" "$prefix/share/hysar" | head -3)"
fi

# Run from a folder that is neither tree.
mkdir "$dir/run" && cd "$dir/run"
"$prefix/bin/hysar" --help > help.txt || fail "installed hysar --help failed"
grep -q "usage: hysar" help.txt || fail "installed hysar --help printed no usage"
for c in hysar-hmd hysar-projector hysar-loadgen; do
  "$prefix/bin/$c" --help > "$c.txt" 2>&1 || fail "installed $c --help failed"
  grep -q "usage: $c" "$c.txt" || fail "installed $c --help printed no usage"
done
"$prefix/bin/hysar" render --angles 0 --model blinn-phong --no-exr --out "$dir/run/render" \
  > render.log 2>&1 || { tail -20 render.log; fail "installed hysar render failed"; }
[[ -s render/projector.png && -s render/render.json ]] || fail "installed hysar render wrote no projector frame"
python3 - render/render.json <<'PY' || fail "installed hysar render: render.json"
import json, sys
d = json.load(open(sys.argv[1]))
vd = [i for i in d["images"] if i["kind"] == "viewer-vd"]
assert len(vd) == 2, f"{len(vd)} VD layers"
assert d["disagreements"] == [], d["disagreements"]
PY

# The unit: ExecStart is the installed binary, and systemd finds nothing to warn about.
unit="$prefix/lib/systemd/system/hysar.service"
grep -q "^ExecStart=$prefix/bin/hysar serve " "$unit" || fail "hysar.service does not start $prefix/bin/hysar: $(grep ExecStart= "$unit")"
if command -v systemd-analyze > /dev/null; then
  out=$(systemd-analyze verify --man=no "$unit" 2>&1) || { echo "$out"; fail "systemd-analyze verify failed"; }
  [[ -z "$out" ]] || { echo "$out"; fail "systemd-analyze verify warned"; }
  echo "install test: systemd-analyze verify: hysar.service clean"
else
  echo "install test: systemd-analyze not on this machine; the unit's syntax was not verified"
fi

# The Containerfile (not built here: CI has no container engine) builds with every library the
# build needs: each -dev package of scripts/setup.sh but the test-only ones is in its list.
grep -q "cmake --install /build" "$src/Containerfile" || fail "the Containerfile does not install the build"
grep -q '"/usr/bin/hysar", "serve"' "$src/Containerfile" || fail "the Containerfile does not run hysar serve"
for p in $(sed -n '/^PACKAGES=(/,/^)/p' "$src/scripts/setup.sh" | tr ' ' '\n' | grep -- '-dev$'); do
  case "$p" in libgtest-dev|libbenchmark-dev|libclang-rt-*) continue ;; esac
  grep -qw -- "$p" "$src/Containerfile" || fail "the Containerfile's build stage lacks $p (scripts/setup.sh installs it)"
done
echo "install test: $(find "$prefix" -type f | wc -l) files installed; the installed hysar renders"
