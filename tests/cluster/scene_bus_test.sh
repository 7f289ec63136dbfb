#!/usr/bin/env bash
# Runs the SceneBus tests against a nats-server with JetStream on a free loopback port and a
# temporary store. Usage: scene_bus_test.sh TEST_BINARY
set -euo pipefail
dir=$(mktemp -d)
nats=""
nats_tls=""
cleanup() { for p in $nats $nats_tls; do kill -KILL "$p" 2>/dev/null; done; rm -rf "$dir"; }
trap cleanup EXIT
command -v nats-server > /dev/null || { echo "FAIL: nats-server is not installed (scripts/setup.sh)"; exit 1; }
port=$(python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])')
nats-server -js -a 127.0.0.1 -p "$port" -sd "$dir/js" > "$dir/nats.log" 2>&1 &
nats=$!
for _ in $(seq 100); do grep -q "Server is ready" "$dir/nats.log" && break; sleep 0.1; done
grep -q "Server is ready" "$dir/nats.log" || { echo "FAIL: nats-server did not start"; cat "$dir/nats.log"; exit 1; }
# A second one with TLS (a self-signed certificate for 127.0.0.1) and a token.
openssl req -x509 -newkey ec -pkeyopt ec_paramgen_curve:prime256v1 -nodes -days 2 \
  -subj /CN=127.0.0.1 -addext subjectAltName=IP:127.0.0.1 -keyout "$dir/bus.key" \
  -out "$dir/bus.pem" 2> /dev/null
tls_port=$(python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])')
nats-server -js -a 127.0.0.1 -p "$tls_port" -sd "$dir/js-tls" --tls --tlscert "$dir/bus.pem" \
  --tlskey "$dir/bus.key" --auth bus-test-token > "$dir/nats-tls.log" 2>&1 &
nats_tls=$!
for _ in $(seq 100); do grep -q "Server is ready" "$dir/nats-tls.log" && break; sleep 0.1; done
grep -q "Server is ready" "$dir/nats-tls.log" || { echo "FAIL: nats-server with TLS did not start"; cat "$dir/nats-tls.log"; exit 1; }
HYSAR_TEST_NATS_URL="nats://127.0.0.1:$port" HYSAR_TEST_NATS_TLS_URL="tls://127.0.0.1:$tls_port" \
  HYSAR_TEST_NATS_CA="$dir/bus.pem" HYSAR_TEST_NATS_TOKEN="bus-test-token" "$1"
