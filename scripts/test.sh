#!/usr/bin/env bash
# Set-up, then the whole test suite through ctest (GPU tests on lavapipe, validation on).
# HYSAR_FUZZ_SECONDS=N runs the decoder fuzzer for N seconds instead of 30;
# HYSAR_SOAK=1 adds the long reliability runs (see README, "Long runs").
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh -DHYSAR_WERROR=ON
scripts/check_layers.sh
scripts/check_format.sh
jobs=$(nproc 2>/dev/null || echo 2)
# The server's tests that run under AddressSanitizer below. The plain build's ctest leaves them
# out: each runs once under ASan and UBSan (and most once more under TSan), not a third time.
server_tests='^(ServerTest|Loopback|Reliability|IdleTimeout|ProtocolRules|ProtocolDoc|ClientLib|net\.scale|net\.tls|net\.cluster|cluster\.)'
# The protocol and the server again under AddressSanitizer + UndefinedBehaviorSanitizer (clang):
# the protocol tests (leak checking on), the decoders' libFuzzer run, the server's loopback and
# reliability tests and the scale test. Leak checking is off for those that load the Vulkan
# driver: Mesa frees some allocations only when it is unloaded, where LeakSanitizer can no
# longer name them.
CC=clang CXX=clang++ cmake -S . -B build-san -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DHYSAR_SANITIZE=ON \
  -DCMAKE_UNITY_BUILD=ON -DHYSAR_WERROR=ON -DHYSAR_FUZZ_SECONDS="${HYSAR_FUZZ_SECONDS:-30}" >/dev/null
cmake --build build-san -j "$jobs" --target hs_protocol_tests hs_fuzz_decoder hs_fuzz_seeds hs_net_tests hysar \
  hysar-loadgen hysar-hmd hysar-projector hs_client_lib_tests hs_scene_bus_tests
(cd build-san && ctest --output-on-failure -j "$jobs" --timeout 600 -R '^(Protocol|Tiles|protocol)\.' &&
  ASAN_OPTIONS=detect_leaks=0:handle_abort=1 UBSAN_OPTIONS=print_stacktrace=1 \
    ctest --output-on-failure -j "$jobs" --timeout 600 -R "$server_tests")

# The server's loopback and reliability tests, and the render thread's worker pool, once more
# under ThreadSanitizer; tests/tsan.supp lists the suppressions (the Vulkan driver only) and why.
CC=clang CXX=clang++ cmake -S . -B build-tsan -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DHYSAR_TSAN=ON \
  -DCMAKE_UNITY_BUILD=ON -DHYSAR_WERROR=ON >/dev/null
cmake --build build-tsan -j "$jobs" --target hs_net_tests hs_client_lib_tests hs_worker_pool_tests
(cd build-tsan &&
  TSAN_OPTIONS="halt_on_error=1 second_deadlock_stack=1 suppressions=$PWD/../tests/tsan.supp" \
    ctest --output-on-failure -j "$jobs" --timeout 900 -R '^(ServerTest|Loopback|Reliability|IdleTimeout|ProtocolRules|ClientLib|WorkerPool)')

cd build
ctest --output-on-failure -j "$jobs" --timeout 900 -E "$server_tests"
