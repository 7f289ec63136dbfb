#!/usr/bin/env bash
# Set-up, then the whole test suite through ctest (GPU tests on lavapipe, validation on).
# Long sweeps and soaks run only with HYSAR_LONG_TESTS=1 (see README).
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh
scripts/check_layers.sh
jobs=$(nproc 2>/dev/null || echo 2)
cd build
ctest --output-on-failure -j "$jobs" --timeout 900
