#!/usr/bin/env bash
# The scene bus with a .creds file (a user JWT and its nkey seed; docs/CLUSTER.md, "Credentials
# and TLS to the bus"), on loopback: a nats-server in operator mode with an account made by
# nats_creds.py (as nsc would make it);
#   1. a node started with --cluster-creds connects, puts its scene as version 1, and a push
#      through it is confirmed by the bus;
#   2. a node with the .creds of another operator's user is refused by the bus, and says so;
#   3. a .creds file others may read is refused before connecting, naming it.
set -euo pipefail
bin="$1"
source "$(dirname "$0")/cluster_lib.sh"
(umask 077 && echo "creds-test-token" > "$dir/token" && echo "creds-test-admin" > "$dir/admin")
mkdir "$dir/ours" "$dir/theirs"
python3 "$src/tests/cluster/nats_creds.py" "$dir/ours" || fail "cannot make the operator, account and user"
python3 "$src/tests/cluster/nats_creds.py" "$dir/theirs" || fail "cannot make the other operator's user"
np=$(free_port)
url="nats://127.0.0.1:$np"
cat > "$dir/nats.conf" <<EOF
listen: 127.0.0.1:$np
jetstream { store_dir: "$dir/js" }
include ours/resolver.conf
EOF
nats-server -c "$dir/nats.conf" > "$dir/nats.log" 2>&1 &
servers+=($!)
nats_ready "$dir/nats.log"

# 1. The node user's .creds: connected, version 1, a push confirmed.
node_flags=(--cluster-creds "$dir/ours/node.creds")
start_node a
grep -q "^cluster: node 'a' on $url, scene version 1$" "$dir/node-a.log" \
  || fail "node a did not put version 1: $(grep -E 'cluster|error' "$dir/node-a.log")"
push a first > "$dir/push.log" 2>&1 || fail "push through a: $(cat "$dir/push.log")"
within 10 'same_everywhere 2 a' || fail "version 2 not applied on a: $(applied a)"
echo "1. --cluster-creds: node a on the bus in operator mode; version 1, then 2 pushed"

# 2. Another operator's user: the bus refuses it, the node exits naming the bus and why.
node_flags=(--cluster-creds "$dir/theirs/node.creds")
launch_node b
for _ in $(seq 300); do kill -0 "$pid_b" 2>/dev/null || break; sleep 0.1; done
! kill -0 "$pid_b" 2>/dev/null || fail "node b with another operator's .creds is still running"
grep -q "cannot connect to the scene bus.*Authorization Violation" "$dir/node-b.log" \
  || fail "node b did not say the bus refused it: $(tail -3 "$dir/node-b.log")"
echo "2. another operator's user: refused by the bus ($(grep -oE 'Authorization Violation' "$dir/node-b.log"))"

# 3. A .creds that others may read: refused before connecting, naming the file.
cp "$dir/ours/node.creds" "$dir/open.creds"
chmod 644 "$dir/open.creds"
node_flags=(--cluster-creds "$dir/open.creds")
launch_node c
for _ in $(seq 300); do kill -0 "$pid_c" 2>/dev/null || break; sleep 0.1; done
! kill -0 "$pid_c" 2>/dev/null || fail "node c with a world-readable .creds is still running"
grep -q "open.creds" "$dir/node-c.log" || fail "node c did not name its .creds: $(tail -3 "$dir/node-c.log")"
echo "3. a .creds others may read: refused ($(grep -m1 -oE "[^:]*open.creds[^;]*" "$dir/node-c.log" | head -c 160))"
