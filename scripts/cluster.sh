#!/usr/bin/env bash
# Three nats-servers with JetStream (the scene bucket in three replicas), two render nodes
# sharing its scene, and HAProxy in front of them,
# on loopback (docs/CLUSTER.md), each with its own ports and temp folders: a projector, a headset
# and four load-generating headsets go through the gateway's one address; HAProxy's table shows
# where each landed; a scene pushed to one node is served by both; everything is stopped by PID.
# Usage: scripts/cluster.sh [BUILD_DIR]   (default build/; scripts/setup.sh builds it and installs
# haproxy and nats-server). Leaves its pictures in out/cluster/.
set -euo pipefail
cd "$(dirname "$0")/.."
bin="${1:-build}"
[[ -x "$bin/hysar" ]] || { echo "cluster.sh: no $bin/hysar (run scripts/setup.sh)" >&2; exit 1; }
for tool in haproxy nats-server; do
  command -v $tool > /dev/null || { echo "cluster.sh: $tool is not installed (scripts/setup.sh)" >&2; exit 1; }
done
dir=$(mktemp -d)
out=out/cluster
mkdir -p "$out"
pids=()
stop_all() { for p in "${pids[@]}"; do kill -TERM "$p" 2>/dev/null || true; done; wait 2>/dev/null || true; rm -rf "$dir"; }
trap stop_all EXIT
free_port() { python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])'; }
gw=$(free_port)
(umask 077 && head -c 16 /dev/urandom | od -An -tx1 | tr -d ' \n' > "$dir/token" &&
  head -c 16 /dev/urandom | od -An -tx1 | tr -d ' \n' > "$dir/admin-token")
# The scene bus: three nats-servers in one NATS cluster, the bucket in three replicas (an update
# is confirmed once two of them stored it; any one may die).
client_ports=() route_ports=()
for i in 0 1 2; do client_ports+=("$(free_port)"); route_ports+=("$(free_port)"); done
routes=$(for p in "${route_ports[@]}"; do printf 'nats-route://127.0.0.1:%s,' "$p"; done)
for i in 0 1 2; do
  cat > "$dir/nats-$i.conf" <<EOF
server_name: bus$i
listen: 127.0.0.1:${client_ports[$i]}
jetstream { store_dir: "$dir/jetstream-$i" }
cluster { name: hysar-bus, listen: 127.0.0.1:${route_ports[$i]}, routes: [${routes%,}] }
EOF
  nats-server -c "$dir/nats-$i.conf" > "$dir/nats-$i.log" 2>&1 &
  pids+=($!)
done
bus=$(for p in "${client_ports[@]}"; do printf 'nats://127.0.0.1:%s,' "$p"; done)
bus=${bus%,}
echo "scene bus: $bus (three nats-servers, replicas 3)"
for _ in $(seq 300); do grep -qh "JetStream cluster new metadata leader" "$dir"/nats-*.log && break; sleep 0.1; done

nodes=()
for n in a b; do
  port=$(free_port); agent=$(free_port)
  mkdir -p "$dir/$n"
  LP_NUM_THREADS=1 "$bin/hysar" serve --listen "127.0.0.1:$port" --agent-port "$agent" \
    --drain-file "$dir/$n/drain" --token-file "$dir/token" --admin-token-file "$dir/admin-token" \
    --cluster "$bus" --cluster-replicas 3 --node-id "$n" > "$dir/$n/serve.log" 2>&1 &
  pids+=($!)
  for _ in $(seq 300); do grep -q "^serving" "$dir/$n/serve.log" && break; sleep 0.1; done
  nodes+=(--node "$n=127.0.0.1:$port,agent=$agent")
  eval "port_$n=$port"
  echo "node $n: 127.0.0.1:$port, agent-check on $agent (pid $!)"
done
"$bin/hysar" cluster config --listen "127.0.0.1:$gw" --admin-socket "$dir/haproxy.sock" "${nodes[@]}" \
  --out "$dir/haproxy.cfg" > /dev/null
haproxy -c -q -f "$dir/haproxy.cfg"
haproxy -db -f "$dir/haproxy.cfg" > "$dir/haproxy.log" 2>&1 &
pids+=($!)
echo "gateway: 127.0.0.1:$gw (haproxy pid $!)"

show() {
  python3 scripts/haproxy_stat.py "$dir/haproxy.sock" |
    awk 'BEGIN {printf "%-14s%-6s%-16s%7s%10s\n", "backend", "node", "status", "weight", "sessions"}
         {printf "%-14s%-6s%-16s%7s%10s\n", $1, $2, $3, $4, $5}'
}
for _ in $(seq 100); do
  [[ -S "$dir/haproxy.sock" ]] && [[ $(show | grep -c " UP ") -ge 4 ]] && break
  sleep 0.2
done

common=(--connect "127.0.0.1:$gw" --token-file "$dir/token")
"$bin/clients/hysar-projector" "${common[@]}" --frames 1 --out "$out"
"$bin/clients/hysar-hmd" "${common[@]}" --angles -20,20 --scale 0.25 --name through-gateway --out "$out"
echo "four headsets for 5 s through the gateway:"
"$bin/clients/hysar-loadgen" "${common[@]}" --viewers 4 --rate 15 --seconds 5 --scale 0.25 \
  > "$dir/loadgen.log" 2>&1 &
loadgen=$!
sleep 3
show
wait "$loadgen" || { cat "$dir/loadgen.log"; exit 1; }
grep -E "layers/s total|latency p50" "$dir/loadgen.log"
echo "a scene pushed to node a (the room renamed), served by both:"
sed 's/"name": "HySAR experiment 1 room[^"]*"/"name": "the room, pushed once"/' configs/exp1-room.json > "$dir/room.json"
"$bin/hysar" admin --connect "127.0.0.1:$port_a" --token-file "$dir/admin-token" scene push "$dir/room.json"
sleep 1
for n in a b; do echo "  node $n: $(grep -E "scene version [0-9]+:" "$dir/$n/serve.log" | tail -n 1 | sed 's/.*info  //')"; done
echo "pictures in $out/; stopping the nodes and the gateway"
