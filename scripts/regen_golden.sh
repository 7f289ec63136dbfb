#!/usr/bin/env bash
# Regenerates the golden images in tests/data/golden/ (docs/SHADING.md, "Golden images"):
# builds hs_gpu_tests if needed, runs the golden tests with HYSAR_REGEN_GOLDEN=1 (each test
# renders its image as golden.json describes it and writes it there instead of comparing), then
# shows what changed.
#
# Regenerate deliberately, never to make a failing test pass without knowing why. Look at the
# new images (e.g. the PNGs a failed comparison wrote under <build>/tests/golden-failures/)
# and commit a regeneration with a line in the commit message saying why the renders changed,
# and on which driver they were generated ("Goldens generated on lavapipe (llvmpipe, LLVM 15)
# from commit <hash>"). Generate them on lavapipe, where CI compares them.
#
# Usage: scripts/regen_golden.sh [build-dir] [gtest filter]
#   build-dir     default: build (configured with CMake if it does not exist)
#   gtest filter  default: Golden/* (all goldens); e.g. 'Golden/*ward*' for some of them
set -euo pipefail
cd "$(dirname "$0")/.."
build="${1:-build}"
filter="${2:-Golden/*}"

if [[ ! -f "$build/build.ninja" && ! -f "$build/Makefile" ]]; then
  cmake -S . -B "$build" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo
fi
cmake --build "$build" --target hs_gpu_tests -j"${JOBS:-2}"

# Validation on, as in CI: a validation message fails the test and no golden is written by it.
log="$(mktemp)"
trap 'rm -f "$log"' EXIT
status=0
(cd "$build" && HYSAR_VALIDATION=1 HYSAR_REGEN_GOLDEN=1 ./tests/hs_gpu_tests --gtest_filter="$filter") |
  tee "$log" || status=$?

echo
echo "Goldens regenerated from commit $(git rev-parse --short HEAD) on" \
  "$(sed -n 's/^\[gpu\] device: //p' "$log" | head -1)."
git status --short -- tests/data/golden
du -sh tests/data/golden
if [[ $status -ne 0 ]]; then
  echo "some goldens were not regenerated (a test failed above)" >&2
  exit "$status"
fi
