#!/usr/bin/env bash
# Set-up, then the whole test suite through ctest (GPU tests on lavapipe, validation on).
# Long sweeps and soaks run only with HYSAR_LONG_TESTS=1 (see README).
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh
scripts/check_layers.sh
jobs=$(nproc 2>/dev/null || echo 2)
# The wire format again under AddressSanitizer + UndefinedBehaviorSanitizer (clang), with the
# decoder's libFuzzer target run for a bounded time.
CC=clang CXX=clang++ cmake -S . -B build-san -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  -DHYSAR_PROTOCOL_ONLY=ON -DHYSAR_SANITIZE=ON >/dev/null
cmake --build build-san -j "$jobs"
(cd build-san && ctest --output-on-failure -j "$jobs" --timeout 300)

cd build
ctest --output-on-failure -j "$jobs" --timeout 900
