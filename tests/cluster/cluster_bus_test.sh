#!/usr/bin/env bash
# Render nodes sharing one scene through NATS JetStream (hysar serve --cluster, docs/CLUSTER.md),
# on loopback: counts and orders, not frame rates; each step bounded.
#   0. each node's heartbeat on node.<id> carries its version and load;
#   1. 5 SceneUpdates back to back, to either node: both apply strictly increasing versions and
#      end on the same one; the projector receives the final version;
#   2. two updates written from the same version: one wins on both nodes, the other gets the
#      conflict ("scene changed concurrently, now version N"), and is not applied;
#   3. nats-server stopped: layers keep flowing, SceneUpdate gets the bus error; after its
#      restart, an update reaches both nodes;
#   3b. nats-server killed while a writer waits to learn whether an update was stored: the
#      writer looks again once it is back, and its refusal holds;
#   4. a third node started late serves the latest version from its first Welcome;
#   5. nats-server restarted without its store, and the third node restarted on the empty bus
#      (it puts its own scene there as version 1): the nodes still running put the acknowledged
#      scene back, so every node converges on it at one version, and the next push reaches all.
set -euo pipefail
bin="$1"
source "$(dirname "$0")/cluster_lib.sh"
nats=""
(umask 077 && echo "bus-test-token" > "$dir/token" && echo "bus-test-admin" > "$dir/admin")
np=$(free_port)
url="nats://127.0.0.1:$np"
start_nats() {
  nats-server -js -a 127.0.0.1 -p "$np" -sd "$dir/js" > "$dir/nats.log" 2>&1 &
  nats=$!
  servers+=($nats)
  nats_ready "$dir/nats.log"
}
# Here a version counts once applied (the start-up line has no colon).
applied() { grep -oE "scene version [0-9]+:" "$dir/node-$1.log" | grep -oE "[0-9]+" | tr '\n' ' '; }
increasing() { python3 -c "import sys; v=[int(x) for x in sys.argv[1:]]; sys.exit(0 if all(a<b for a,b in zip(v,v[1:])) else 1)" $(applied "$1"); }

start_nats
start_node a
start_node b
grep -q "scene version 1$" "$dir/node-a.log" || fail "the first node did not put version 1"
grep -q "scene version 1$" "$dir/node-b.log" || fail "the second node did not start on version 1"
mkdir "$dir/p"
"$bin/clients/hysar-projector" --connect "127.0.0.1:$port_a" --token-file "$dir/token" --frames 0 \
  --out "$dir/p" > "$dir/projector.log" 2>&1 &
pids+=($!)
"$bin/clients/hysar-loadgen" --connect "127.0.0.1:$port_b" --token-file "$dir/token" --viewers 2 \
  --rate 10 --seconds 0 --scale 0.2 > "$dir/loadgen.log" 2>&1 &
pids+=($!)

# 0. Heartbeats: each node publishes its version and load on node.<id> (NATS text protocol).
python3 - "$np" > "$dir/heartbeats.txt" <<'PY' || fail "no heartbeat from both nodes within 6 s"
import json, socket, sys, time
s = socket.create_connection(("127.0.0.1", int(sys.argv[1])), timeout=6)
s.sendall(b'CONNECT {"verbose":false}\r\nSUB node.* 1\r\n')
f = s.makefile("rb")
seen, end = {}, time.time() + 6
while len(seen) < 2 and time.time() < end:
    line = f.readline().decode().strip()
    if line.startswith("PING"):
        s.sendall(b"PONG\r\n")
    if not line.startswith("MSG"):
        continue
    payload = json.loads(f.read(int(line.split()[-1]) + 2)[:-2])
    seen[payload["node"]] = payload
assert set(seen) == {"a", "b"}, seen
for n, p in sorted(seen.items()):
    assert p["scene_version"] == 1 and p["port"] > 0 and "sessions" in p, p
    print(n, json.dumps(p))
PY
echo "heartbeats: $(tr '\n' ' ' < "$dir/heartbeats.txt")"

# 1. Five updates back to back, alternating nodes.
for i in 1 2 3 4 5; do
  node=$([[ $((i % 2)) == 1 ]] && echo a || echo b)
  push "$node" "$i" > "$dir/push.log" 2>&1 || fail "push $i through $node: $(cat "$dir/push.log")"
done
within 10 '[[ "$(last_applied a)" == 6 && "$(last_applied b)" == 6 ]]' \
  || fail "the nodes did not both reach version 6: a: $(applied a); b: $(applied b)"
increasing a && increasing b || fail "versions not strictly increasing: a: $(applied a); b: $(applied b)"
within 10 '[[ -e "$dir/p/projector_v6.png" ]]' || fail "the projector did not receive version 6"
echo "5 updates: a applied $(applied a); b applied $(applied b); projector at v6"

# 2. Two admins on one base version: two SceneUpdates sent back to back on one admin session
#    (raw protocol), so both are normally written from the version node a has taken: one wins,
#    the other gets error 11 naming the version now current; both nodes apply the winner only.
#    (SceneBus.CreateOnceThenCompareAndSet forces the conflict without timing.)
base=$(last_applied a)
sed 's/"name": "HySAR experiment 1 room[^"]*"/"name": "race one"/' "$src/configs/exp1-room.json" > "$dir/race1.json"
sed 's/"name": "HySAR experiment 1 room[^"]*"/"name": "race two"/' "$src/configs/exp1-room.json" > "$dir/race2.json"
python3 - "$port_a" "$dir/admin" "$dir/race1.json" "$dir/race2.json" > "$dir/race.log" 2>&1 <<'PY' || fail "racing admins: $(cat "$dir/race.log")"
import socket, struct, sys, time
port, token = int(sys.argv[1]), open(sys.argv[2], "rb").read().strip()
scenes = [open(p, "rb").read() for p in sys.argv[3:5]]
s = socket.create_connection(("127.0.0.1", port), timeout=10)
frame = lambda t, payload, seq: struct.pack("<IHHII", 0x52535948, 1, t, len(payload), seq) + payload
def recvn(n):
    b = b""
    while len(b) < n:
        c = s.recv(n - len(b))
        if not c:
            raise SystemExit("the server closed the connection")
        b += c
    return b
def read():
    _, _, t, n, seq = struct.unpack("<IHHII", recvn(16))
    return t, seq, recvn(n)
s.sendall(frame(1, bytes([3]) + struct.pack("<H", len(token)) + token + b"\x05\x00racer", 1))
t, _, _ = read()
assert t == 2, f"no Welcome (type {t})"
s.sendall(b"".join(frame(8, struct.pack("<I", len(j)) + j, 2 + i) for i, j in enumerate(scenes)))
errors, end = [], time.time() + 5
s.settimeout(0.5)
while time.time() < end:
    try:
        t, seq, p = read()
    except socket.timeout:
        continue
    if t == 13:
        code, n = struct.unpack("<HH", p[:4])
        errors.append((seq, code, p[4:4 + n].decode()))
# Normally the second is written before the first comes back through the watch and loses; if
# the first came back sooner, the second was based on it and both are taken, in order.
assert len(errors) <= 1, f"expected at most one refusal, got {errors}"
for e in errors:
    assert e[1] == 11 and "scene changed concurrently, now version" in e[2], errors
print(len(errors), errors[0][2] if errors else "both taken in order")
PY
refused=$(cut -d' ' -f1 < "$dir/race.log")
winner=$(( base + 2 - refused ))
within 10 '[[ "$(last_applied a)" == "$winner" && "$(last_applied b)" == "$winner" ]]' \
  || fail "after the race the nodes are not both at $winner: a: $(applied a); b: $(applied b)"
sleep 1
[[ "$(last_applied a)" == "$winner" && "$(last_applied b)" == "$winner" ]] \
  || fail "the losing update was applied too: a: $(applied a); b: $(applied b)"
echo "race: two updates from version $base: $refused refused ($(cut -d' ' -f2- < "$dir/race.log")); v$winner on both"
before_outage=$(last_applied a)

# 3. The bus goes away: layers go on, a push gets the bus error; back, pushes reach both nodes.
frames() {
  "$bin/hysar" admin --connect "127.0.0.1:$port_b" --token-file "$dir/admin" stats --json \
    | python3 -c "import json,sys; print(sum(v.get('frames',0) for v in json.load(sys.stdin).get('viewers',[])))"
}
kill -TERM "$nats"; wait "$nats" 2>/dev/null || true; nats=""
sleep 0.5
f0=$(frames)
if out=$(push a outage 2>&1); then fail "a push during the outage was taken: $out"; fi
grep -q "scene bus is unavailable" <<< "$out" || fail "the push during the outage: $out"
sleep 1
f1=$(frames)
(( f1 > f0 )) || fail "no layers during the bus outage ($f0 -> $f1 frames)"
echo "bus down: push refused ($(grep -o 'the scene bus is unavailable[^;]*' <<< "$out")); frames $f0 -> $f1"
start_nats
restarted=$(date +%s%N)
within 15 'push b after > "$dir/push.log" 2>&1' || fail "no push went through after the bus came back: $(cat "$dir/push.log")"
want=$(grep -oE "applied: scene version [0-9]+" "$dir/push.log" | grep -oE "[0-9]+$")
(( want > before_outage )) || fail "the push after the outage gave version $want (was $before_outage)"
within 10 '[[ "$(last_applied a)" == "$want" && "$(last_applied b)" == "$want" ]]' \
  || fail "after the bus came back the nodes are not both at $want: a: $(applied a); b: $(applied b)"
echo "bus back: version $want on both nodes; the first push through $(( ($(date +%s%N) - restarted) / 1000000 )) ms after the restart"

# 3b. nats-server frozen, a SceneUpdate written to it, then the server killed (-9) while the
#     writer waits to look whether the bus stored it, and restarted on its store: the writer
#     looks again until the bus answers, and its answer holds: refused, and never applied.
kill -STOP "$nats"
push a killed > "$dir/push-killed.log" 2>&1 &
push_pid=$!
sleep 1
kill -KILL "$nats"; wait "$nats" 2>/dev/null || true; nats=""
sleep 5  # well past the write's deadline and the clock margin: the writer is looking
kill -0 "$push_pid" 2>/dev/null \
  || fail "the writer answered while the bus was down, without looking: $(cat "$dir/push-killed.log")"
start_nats
wait "$push_pid" && fail "the update written to a frozen, then killed bus was taken: $(cat "$dir/push-killed.log")"
grep -q "it is refused and stays refused" "$dir/push-killed.log" \
  || fail "the update in flight when the bus was killed: $(cat "$dir/push-killed.log")"
within 15 'push b after-kill > "$dir/push.log" 2>&1' || fail "no push went through after the kill: $(cat "$dir/push.log")"
want=$(grep -oE "applied: scene version [0-9]+" "$dir/push.log" | grep -oE "[0-9]+$")
within 10 '[[ "$(last_applied a)" == "$want" && "$(last_applied b)" == "$want" ]]' \
  || fail "after the kill the nodes are not both at $want: a: $(applied a); b: $(applied b)"
sleep 1
if grep -q "'room killed'" "$dir"/node-*.log; then fail "the refused update was applied later"; fi
echo "bus killed mid-update: refused ($(grep -o 'did not confirm[^;]*' "$dir/push-killed.log")), never applied; version $want on both"
# The nodes' scene is now 'room after-kill'.

# 4. A late node serves the latest version from its first Welcome.
start_node c
grep -q "scene version $want$" "$dir/node-c.log" || fail "the late node did not start on version $want: $(head -3 "$dir/node-c.log")"
welcome=$(python3 - "$port_c" "$dir/token" <<'PY'
import socket, struct, sys
s = socket.create_connection(("127.0.0.1", int(sys.argv[1])), timeout=10)
token = open(sys.argv[2], "rb").read().strip()
hello = bytes([2]) + struct.pack("<H", len(token)) + token + struct.pack("<H", 4) + b"late"
s.sendall(struct.pack("<IHHII", 0x52535948, 1, 1, len(hello), 1) + hello)
h = b""
while len(h) < 16 + 16:
    h += s.recv(64)
_, _, t, n, _ = struct.unpack("<IHHII", h[:16])
assert t == 2, f"no Welcome (type {t})"
print(struct.unpack("<IQI", h[16:32])[2])
PY
) || fail "no Welcome from the late node"
[[ "$welcome" == "$want" ]] || fail "the late node's Welcome says version $welcome, expected $want"
"$bin/clients/hysar-projector" --connect "127.0.0.1:$port_c" --token-file "$dir/token" --frames 1 \
  --out "$dir/pc" > "$dir/late-projector.log" 2>&1 || fail "projector on the late node"
[[ -e "$dir/pc/projector_v$want.png" ]] || fail "the late node's projector frame is not v$want: $(ls "$dir/pc")"
echo "late node: version $want at start and in its Welcome; nodes applied a: $(applied a); b: $(applied b); c: $(applied c)"

# 5. The bus comes back empty: nothing acknowledged is lost and the cluster does not split.
kill -KILL "$nats"; wait "$nats" 2>/dev/null || true; nats=""
kill -KILL "$pid_c" 2>/dev/null || true  # the late node
wait "$pid_c" 2>/dev/null || true
rm -rf "$dir/js" "$dir/node-c.log"
start_nats
start_node c
# It puts its own scene as version 1, unless a running node refilled the bus first (they look
# every 2 s): then it starts on the refilled version.
c_start=$(grep -oE "^cluster: node 'c' on .*scene version [0-9]+$" "$dir/node-c.log" | grep -oE "[0-9]+$")
[[ -n "$c_start" ]] || fail "the restarted node printed no start-up version"
named() { grep -oE "scene version [0-9]+: '[^']*'" "$dir/node-$1.log" | tail -n 1; }
# The version a node holds: the last it applied, or, where it applied none, the one it started
# on (the restarted node starts on the refilled version when it reads the bus after the refill;
# that version is the running nodes' scene, named on their side).
held() {
  local v; v=$(named "$1" | grep -oE "^scene version [0-9]+" | grep -oE "[0-9]+$")
  [[ -n "$v" ]] || v=$(grep -oE "^cluster: node '$1' on .*scene version [0-9]+$" "$dir/node-$1.log" | grep -oE "[0-9]+$")
  echo "$v"
}
within 20 '[[ -n "$(held a)" && "$(held a)" == "$(held b)" && "$(held b)" == "$(held c)" && "$(named a)" == *"room after-kill"* && "$(named b)" == *"room after-kill"* ]]' \
  || fail "the cluster did not converge on the acknowledged scene after the bus came back empty: a: $(named a); b: $(named b); c: $(named c) (holds version $(held c), started on $c_start)"
refilled=$(last_applied a)
refilled_name=$(named a | cut -d"'" -f2)
(( refilled >= want )) || fail "the refilled version $refilled is below the acknowledged $want"
within 15 'push c refill > "$dir/push.log" 2>&1' || fail "no push went through after the refill: $(cat "$dir/push.log")"
now=$(grep -oE "applied: scene version [0-9]+" "$dir/push.log" | grep -oE "[0-9]+$")
within 10 '[[ "$(last_applied a)" == "$now" && "$(last_applied b)" == "$now" && "$(last_applied c)" == "$now" ]]' \
  || fail "the push after the refill did not reach every node at $now: a: $(applied a); b: $(applied b); c: $(applied c)"
grep -q "put the held scene back\|put the newer write" "$dir/node-a.log" "$dir/node-b.log" \
  || fail "no node says it refilled the bus"
echo "bus back empty: c started on version $c_start, the held '$refilled_name' went back as version $refilled on every node; the next push is version $now on all three"
echo "scene bus: ordered versions on every node, conflict, outage and catch-up behave"
