#!/usr/bin/env bash
# The scene bus on a three-server NATS cluster with the bucket in three replicas
# (docs/CLUSTER.md, "Three replicas"; the servers configured as docs/OPERATIONS.md, "The scene
# bus", shows: TLS, mutual TLS on the routes, a node user), on loopback:
#   0. a node started while only two of the three servers are up waits for the third (the
#      bucket's three replicas cannot be placed before) instead of exiting;
#   1. two render nodes given every server's URL (no --cluster-replicas: three is the default
#      there) make the bucket in three replicas, put and share version 1, then 2;
#   2. one nats-server killed (-9) while a SceneUpdate is in flight: that update is acknowledged
#      and applied, or refused and never lands; no node stops; the next SceneUpdate is confirmed
#      (a majority of two stores it) and reaches both nodes;
#   3. a third node started afterwards starts on that version: nothing acknowledged was lost;
#   4. a projector is served that version, equal on every node.
set -euo pipefail
bin="$1"
source "$(dirname "$0")/cluster_lib.sh"
(umask 077 && echo "replica-test-token" > "$dir/token" && echo "replica-test-admin" > "$dir/admin")
client_ports=() route_ports=() monitor_ports=()
for i in 1 2 3; do
  client_ports+=("$(free_port)"); route_ports+=("$(free_port)"); monitor_ports+=("$(free_port)")
done
# The servers as docs/OPERATIONS.md runs them: TLS to the clients, mutual TLS between the
# servers (one self-signed certificate for 127.0.0.1 here, which is also the CA), and the nodes'
# own user with a password from a file.
openssl req -x509 -newkey ec -pkeyopt ec_paramgen_curve:prime256v1 -nodes -days 2 \
  -subj /CN=127.0.0.1 -addext subjectAltName=IP:127.0.0.1 -keyout "$dir/bus.key" \
  -out "$dir/bus.pem" 2> /dev/null
(umask 077 && echo "node-password-$RANDOM$RANDOM" > "$dir/bus-password")
export NODE_PASSWORD
NODE_PASSWORD=$(cat "$dir/bus-password")
routes=$(for p in "${route_ports[@]}"; do printf 'nats-route://127.0.0.1:%s,' "$p"; done)
routes="[${routes%,}]"
start_server() {  # INDEX
  local i=$1
  cat > "$dir/n$i.conf" <<EOF
server_name: n$i
listen: 127.0.0.1:${client_ports[$i]}
http: 127.0.0.1:${monitor_ports[$i]}
tls { cert_file: "$dir/bus.pem", key_file: "$dir/bus.key" }
jetstream { store_dir: "$dir/js-n$i" }
cluster {
  name: hysar-bus
  listen: 127.0.0.1:${route_ports[$i]}
  tls { cert_file: "$dir/bus.pem", key_file: "$dir/bus.key", ca_file: "$dir/bus.pem", verify: true }
  routes: $routes
}
authorization { users = [ { user: node, password: \$NODE_PASSWORD } ] }
EOF
  nats-server -c "$dir/n$i.conf" > "$dir/nats-n$i.log" 2>&1 &
  servers+=($!)
}
start_server 0
start_server 1
leader() { grep -qh "JetStream cluster new metadata leader" "$dir"/nats-n*.log; }
within 30 leader || fail "two nats-servers elected no JetStream leader within 30 s"
url=$(for p in "${client_ports[@]}"; do printf 'tls://127.0.0.1:%s,' "$p"; done)
url=${url%,}
# No --cluster-replicas: three copies are the default where three servers are listed.
node_flags=(--cluster-ca "$dir/bus.pem" --cluster-user node --cluster-password-file "$dir/bus-password")

# 0. Node a starts on a bus of two servers: three replicas have no place yet, so it waits.
launch_node a
within 60 'grep -q "waiting up to" "$dir/node-a.log"' ||
  fail "node a did not say it waits for the bus's third server"
kill -0 "$pid_a" || fail "node a exited on a bus still forming"
start_server 2
wait_node a
echo "0. node a waited for the third nats-server and then started"

# 1. Two nodes on the three servers; the bucket is made with three replicas.
start_node b
push a one > "$dir/push.log" 2>&1 || fail "push through a: $(cat "$dir/push.log")"
within 10 'same_everywhere 2 a b' || fail "version 2 not on both nodes: a: $(applied a); b: $(applied b)"
replicas=$(python3 - "${monitor_ports[@]}" <<'PY'
import json, sys, urllib.request
for p in sys.argv[1:]:
    url = f"http://127.0.0.1:{p}/jsz?accounts=true&streams=true&config=true"
    for a in json.load(urllib.request.urlopen(url, timeout=5)).get("account_details", []):
        for st in a.get("stream_detail", []):
            if st.get("name") == "KV_hysar":
                print(st.get("config", {}).get("num_replicas")); sys.exit()
PY
)
[[ "$replicas" == 3 ]] || fail "the bucket has ${replicas:-no} replicas on the servers, not 3"
! grep -q "$NODE_PASSWORD" "$dir"/node-*.log || fail "a node printed the bus password"
echo "1. two nodes on a three-server bus over TLS with a user and password (the bucket in $replicas replicas, the default for three servers): version 2 on both"

# 2. The server that holds node a's watch (its consumer) killed: the nodes stay; an update is
# confirmed by the other two and reaches a, whose watch is stalled until the servers elect a
# new JetStream leader and it is made again (the servers' monitoring says where it lives).
watch_host() {  # NODE: the index of the server leading the node's watch consumer, if found
  python3 - "$1" "${monitor_ports[@]}" <<'PY'
import json, sys, urllib.request
node, ports = sys.argv[1], sys.argv[2:]
get = lambda p, q: json.load(urllib.request.urlopen(f"http://127.0.0.1:{p}/{q}", timeout=5))
subs = set()
for p in ports:
    for c in get(p, "connz?subs=true").get("connections", []):
        if c.get("name") == f"hysar node {node}":
            subs.update(c.get("subscriptions_list", []))
for p in ports:
    for a in get(p, "jsz?accounts=true&streams=true&consumers=true&config=true").get("account_details", []):
        for st in a.get("stream_detail", []):
            for co in st.get("consumer_detail", []) or []:
                if co.get("config", {}).get("deliver_subject") in subs:
                    print(co.get("cluster", {}).get("leader", "")[1:]); sys.exit()
PY
}
victim=$(watch_host a || true)
[[ "$victim" =~ ^[0-2]$ ]] || fail "the servers' monitoring shows no watch consumer of node a"
# Killed 0.3 s into a push (before, during or after its write reaches the bus, as the machine's
# load decides): the push is either acknowledged (then it must survive) or refused (then it must
# never land); the next push is confirmed by the other two.
push b mid > "$dir/push-mid.log" 2>&1 &
push_pid=$!
sleep 0.3
{ kill -KILL "${servers[$victim]}"; wait "${servers[$victim]}"; } 2>/dev/null || true
killed=$(date +%s%N)
mid_v=""
if wait "$push_pid"; then
  mid_v=$(grep -oE "applied: scene version [0-9]+" "$dir/push-mid.log" | grep -oE "[0-9]+$" || true)
  [[ -n "$mid_v" ]] || fail "the push in flight answered without a version: $(cat "$dir/push-mid.log")"
  mid="acknowledged as v$mid_v"
else
  grep -qE "refused|unavailable|changed concurrently" "$dir/push-mid.log" \
    || fail "the push in flight: $(cat "$dir/push-mid.log")"
  mid="refused"
fi
within 60 'push b two > "$dir/push.log" 2>&1' || fail "no push confirmed after a server was killed: $(cat "$dir/push.log")"
after_ms=$(( ($(date +%s%N) - killed) / 1000000 ))
want=$(grep -oE "applied: scene version [0-9]+" "$dir/push.log" | grep -oE "[0-9]+$")
confirmed=$(date +%s%N)
within 10 'same_everywhere $want a b' || fail "version $want not on both nodes: a: $(applied a); b: $(applied b)"
reached_ms=$(( ($(date +%s%N) - confirmed) / 1000000 ))
kill -0 "$pid_a" && kill -0 "$pid_b" || fail "a node stopped when a bus server was killed"
caught=$(grep -c "read directly" "$dir/node-a.log" || true)
if [[ "$mid" == refused ]]; then
  ! grep -q "'room mid'" "$dir"/node-*.log || fail "the refused push landed: $(grep "'room mid'" "$dir"/node-*.log)"
else
  # Acknowledged: the next push followed it (a node that catches up may apply only the newer).
  (( mid_v < want )) || fail "the push acknowledged mid-kill ($mid) is not below v$want"
  grep -q "'room mid'" "$dir/node-b.log" || fail "the push acknowledged mid-kill ($mid) never reached node b, its writer"
fi
echo "2. nats-server n$victim (holding node a's watch) killed during a push (that push $mid): the next push confirmed ${after_ms} ms after the kill by the other two; v$want on a and b ${reached_ms} ms after that (a read it directly, its watch behind: $caught time(s))"

# 3. A node started now finds the acknowledged version.
start_node c
grep -q "scene version $want$" "$dir/node-c.log" || fail "node c did not start on version $want: $(grep cluster "$dir/node-c.log")"
echo "3. a node started after the kill starts on v$want: nothing acknowledged was lost"

# 4. A projector is served that version; every node holds it.
mkdir "$dir/p"
"$bin/clients/hysar-projector" --connect "127.0.0.1:$port_c" --token-file "$dir/token" --frames 1 \
  --out "$dir/p" > "$dir/projector.log" 2>&1 || fail "projector on node c"
[[ -e "$dir/p/projector_v$want.png" ]] || fail "the projector frame is not v$want: $(ls "$dir/p")"
same_everywhere "$want" a b c || fail "the versions differ: a: $(applied a); b: $(applied b); c: $(applied c)"
echo "4. the projector on v$want; a: $(applied a); b: $(applied b); c: $(applied c)"
