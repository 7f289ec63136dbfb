#!/usr/bin/env bash
# Two render nodes behind HAProxy on loopback, with the configuration `hysar cluster config`
# prints (docs/CLUSTER.md): counts and orders, not frame rates; each step bounded.
#   1. the configuration passes `haproxy -c`; a connection that is not a HySAR Hello is refused;
#   2. 4 headsets split 2/2 (plus or minus 1) by leastconn;
#   3. after a node's drain file appears, 2 more headsets all go to the other node;
#   4. kill -9 of a node: every headset is on the other within 3 s, and each one that was on
#      the dead node got layers after its reconnect;
#   5. SIGSTOP of a node (gone without a reset): HAProxy marks it down and its headsets are
#      served by the other;
#   6. TLS terminated at the gateway (--tls-pem): a headset over TLS is served by plain nodes, a
#      plain client is refused.
# The projector goes to the first node. Needs haproxy (scripts/setup.sh installs it).
set -euo pipefail
bin="$1"
haproxy_stat="$(cd "$(dirname "$0")/../../scripts" && pwd)/haproxy_stat.py"
dir=$(mktemp -d)
pids=()
cleanup() {
  for p in "${pids[@]}"; do kill -CONT "$p" 2>/dev/null || true; kill -KILL "$p" 2>/dev/null || true; done
  rm -rf "$dir"
}
trap cleanup EXIT
fail() { echo "FAIL: $*"; for f in "$dir"/*.log; do echo "--- $f"; tail -n 15 "$f"; done; exit 1; }
command -v haproxy > /dev/null || fail "haproxy is not installed (scripts/setup.sh installs it)"
(umask 077 && echo "cluster-test-token" > "$dir/token")

free_port() { python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])'; }
gw=$(free_port); pa=$(free_port); pb=$(free_port); aa=$(free_port); ab=$(free_port)
start_node() {  # NAME PORT AGENT_PORT
  LP_NUM_THREADS=1 "$bin/hysar" serve --listen "127.0.0.1:$2" --agent-port "$3" \
    --drain-file "$dir/drain-$1" --token-file "$dir/token" > "$dir/node-$1.log" 2>&1 &
  eval "node_$1=$!"
  pids+=($!)
}
start_node a "$pa" "$aa"
start_node b "$pb" "$ab"

"$bin/hysar" cluster config --listen "127.0.0.1:$gw" --admin-socket "$dir/haproxy.sock" \
  --node "a=127.0.0.1:$pa,agent=$aa" --node "b=127.0.0.1:$pb,agent=$ab" --out "$dir/haproxy.cfg" > /dev/null
haproxy -c -f "$dir/haproxy.cfg" > "$dir/check.log" 2>&1 || fail "haproxy -c refused the configuration"
haproxy -db -f "$dir/haproxy.cfg" > "$dir/haproxy.log" 2>&1 &
pids+=($!)

# HAProxy's view: "SERVER SESSIONS STATUS" per render node (spaces in the status as '_'), from its runtime API.
stat() {
  python3 "$haproxy_stat" "$dir/haproxy.sock" render_nodes |
    awk '{print $2, $5, $3}'
}
sessions() { stat | awk -v n="$1" '$1 == n {print $2}'; }
status() { stat | awk -v n="$1" '$1 == n {print $3}'; }
# Waits up to $1 seconds for the command in "$2" to succeed.
within() {
  local end=$(( $(date +%s%N) + $1 * 1000000000 ))
  while (( $(date +%s%N) < end )); do eval "$2" && return 0; sleep 0.1; done
  return 1
}
within 20 '[[ -S "$dir/haproxy.sock" && "$(status a)" == UP && "$(status b)" == UP ]]' \
  || fail "HAProxy did not see both nodes up: $(stat 2>&1 | tr '\n' ' ')"

# 1. Not a HySAR Hello: refused by the gateway, no node sees it.
out=$(python3 -c "
import socket
s = socket.create_connection(('127.0.0.1', $gw), timeout=10)
s.sendall(b'GET / HTTP/1.0\r\n\r\n')
print(repr(s.recv(100)))")
[[ "$out" == "b''" ]] || fail "an HTTP request got an answer through the gateway: $out"

common=(--connect "127.0.0.1:$gw" --token-file "$dir/token" --backoff-ms 100)
# 2. Four headsets: leastconn spreads them.
"$bin/clients/hysar-loadgen" "${common[@]}" --viewers 4 --rate 10 --seconds 0 --scale 0.2 \
  --json "$dir/first.json" > "$dir/first.log" 2>&1 &
first=$!
pids+=($first)
within 30 '(( $(sessions a) + $(sessions b) == 4 ))' || fail "4 headsets not connected: $(stat | tr '\n' ' ')"
sa=$(sessions a); sb=$(sessions b)
(( sa >= 1 && sa <= 3 )) || fail "4 headsets split $sa/$sb, expected 2/2 plus or minus 1"
echo "split: a $sa, b $sb"
"$bin/clients/hysar-projector" "${common[@]}" --frames 1 --out "$dir/p" > "$dir/projector.log" 2>&1 \
  || fail "the projector through the gateway"
grep -q "projector 'projector' joined" "$dir/node-a.log" || fail "the projector did not go to node a"

# 3. Drain a: the next two headsets go to b.
touch "$dir/drain-a"
within 10 '[[ "$(status a)" == DRAIN* ]]' || fail "HAProxy did not see a's drain: $(stat | tr '\n' ' ')"
"$bin/clients/hysar-loadgen" "${common[@]}" --viewers 2 --rate 10 --seconds 0 --scale 0.2 \
  --json "$dir/second.json" > "$dir/second.log" 2>&1 &
second=$!
pids+=($second)
within 30 '(( $(sessions a) + $(sessions b) == 6 ))' || fail "6 headsets not connected: $(stat | tr '\n' ' ')"
(( $(sessions a) == sa )) || fail "a took new headsets while draining: $(stat | tr '\n' ' ')"
echo "drain: a $(sessions a), b $(sessions b)"
rm "$dir/drain-a"
within 10 '[[ "$(status a)" == UP ]]' || fail "a did not come back from drain: $(stat | tr '\n' ' ')"

# 4. kill -9 b: everyone on a within 3 s.
kill -KILL "$node_b"
killed=$(date +%s%N)
within 10 '(( $(sessions a) == 6 ))' || fail "not every headset moved to a: $(stat | tr '\n' ' ')"
moved_ms=$(( ($(date +%s%N) - killed) / 1000000 ))
(( moved_ms <= 3000 )) || fail "headsets took $moved_ms ms to reach a (at most 3000)"
echo "kill -9 b: every headset on a after $moved_ms ms"
sleep 1
kill -TERM "$first" "$second"
wait "$first" || fail "loadgen (first) exit $?"
wait "$second" || fail "loadgen (second) exit $?"
python3 - "$dir/first.json" "$dir/second.json" <<'PY' || fail "headsets were not served again after the failover"
import json, sys
moved = 0
for path in sys.argv[1:]:
    for v in json.load(open(path))["per_viewer"]:
        if v["reconnects"] > 0:
            moved += 1
            assert v["layers_since_reconnect"] > 0, f"{path}: viewer {v['viewer']} got no layer after reconnecting"
assert moved > 0, "no headset reconnected: none was on b?"
print(f"{moved} headset(s) reconnected and were served by a")
PY

# 5. SIGSTOP a (with b back): HAProxy marks it down, its headsets are served by b.
start_node b "$pb" "$ab"
within 30 '[[ "$(status b)" == UP ]]' || fail "b did not come back: $(stat | tr '\n' ' ')"
"$bin/clients/hysar-loadgen" "${common[@]}" --viewers 2 --rate 10 --seconds 0 --scale 0.2 \
  --json "$dir/third.json" > "$dir/third.log" 2>&1 &
third=$!
pids+=($third)
within 30 '(( $(sessions a) + $(sessions b) == 2 ))' || fail "2 headsets not connected: $(stat | tr '\n' ' ')"
kill -STOP "$node_a"
stopped=$(date +%s%N)
within 15 '[[ "$(status a)" == DOWN* ]] && (( $(sessions b) == 2 ))' \
  || fail "a stopped: not marked down or its headsets not on b: $(stat | tr '\n' ' ')"
echo "SIGSTOP a: marked down, headsets on b after $(( ($(date +%s%N) - stopped) / 1000000 )) ms"
kill -TERM "$third"
wait "$third" || fail "loadgen (third) exit $?"
kill -CONT "$node_a"
within 15 '[[ "$(status a)" == UP ]]' || fail "a did not come back after SIGCONT: $(stat | tr '\n' ' ')"

# 6. TLS at the gateway (--tls-pem): a headset pinning the gateway's certificate is served by a
#    node that speaks plain; a plain client is refused by HAProxy.
openssl req -x509 -newkey ec -pkeyopt ec_paramgen_curve:prime256v1 -nodes -days 2 -subj /CN=gateway \
  -addext "subjectAltName=IP:127.0.0.1" -keyout "$dir/gw.key" -out "$dir/gw.crt" 2>/dev/null
(umask 077 && cat "$dir/gw.crt" "$dir/gw.key" > "$dir/gw.pem")
tgw=$(free_port)
"$bin/hysar" cluster config --listen "127.0.0.1:$tgw" --tls-pem "$dir/gw.pem" \
  --node "a=127.0.0.1:$pa,agent=$aa" --node "b=127.0.0.1:$pb,agent=$ab" --out "$dir/tls.cfg" > /dev/null
haproxy -c -f "$dir/tls.cfg" > "$dir/tls-check.log" 2>&1 || fail "haproxy -c refused the TLS configuration"
haproxy -db -f "$dir/tls.cfg" > "$dir/haproxy-tls.log" 2>&1 &
pids+=($!)
within 10 'python3 -c "import socket; socket.create_connection((\"127.0.0.1\", $tgw), timeout=1)" 2> /dev/null' \
  || fail "the TLS gateway did not listen"
sleep 2  # its first health checks
"$bin/clients/hysar-hmd" --connect "127.0.0.1:$tgw" --tls-ca "$dir/gw.crt" --token-file "$dir/token" \
  --angles 0 --scale 0.2 --name tls-gw --out "$dir/tls-out" --retries 0 > "$dir/tls-hmd.log" 2>&1 \
  || fail "a headset through the TLS gateway"
ls "$dir"/tls-out/tls-gw_*left*.png > /dev/null || fail "no layer through the TLS gateway"
if "$bin/clients/hysar-hmd" --connect "127.0.0.1:$tgw" --token-file "$dir/token" --angles 0 \
    --scale 0.2 --retries 0 --out "$dir/plain-out" > "$dir/plain-hmd.log" 2>&1; then
  fail "a plain client was served by the TLS gateway"
fi
echo "TLS gateway: served a headset over TLS to plain nodes; refused a plain client ($(tail -n 1 "$dir/plain-hmd.log"))"
echo "cluster gateway: split, drain, kill -9, SIGSTOP and TLS behave"
