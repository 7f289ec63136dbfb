#!/usr/bin/env bash
# Runs the SceneBus tests against a nats-server with JetStream on a free loopback port and a
# temporary store. Usage: scene_bus_test.sh TEST_BINARY
set -euo pipefail
dir=$(mktemp -d)
nats=""
cleanup() { [[ -n "$nats" ]] && kill -KILL "$nats" 2>/dev/null; rm -rf "$dir"; }
trap cleanup EXIT
command -v nats-server > /dev/null || { echo "FAIL: nats-server is not installed (scripts/setup.sh)"; exit 1; }
port=$(python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])')
nats-server -js -a 127.0.0.1 -p "$port" -sd "$dir/js" > "$dir/nats.log" 2>&1 &
nats=$!
for _ in $(seq 100); do grep -q "Server is ready" "$dir/nats.log" && break; sleep 0.1; done
grep -q "Server is ready" "$dir/nats.log" || { echo "FAIL: nats-server did not start"; cat "$dir/nats.log"; exit 1; }
HYSAR_TEST_NATS_URL="nats://127.0.0.1:$port" "$1"
