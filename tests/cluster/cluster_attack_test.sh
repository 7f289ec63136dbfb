#!/usr/bin/env bash
# The scene bus under attack (docs/CLUSTER.md, "Who may change the scene"), on loopback: a
# nats-server with JetStream and two users, "node" (the render nodes, with a password from a
# file, allowed only the scene subjects) and "intruder" (anyone else who can reach NATS, allowed
# everything). Each step ends with the scene version equal on every node:
#   0. the start-up line and the logs never show the bus password;
#   1. an unsigned scene put on the bucket by a plain NATS client is applied by no node;
#   2. poison values on the bucket ("{{{", and a signed value that is no scene): a new node still
#      starts, on the newest signed scene it can serve, and no node applies them;
#   3. 2,000 unsigned values: headsets keep at least half their layers, the nodes apply none,
#      /metrics counts those they saw, a node puts the scene back over them, a node started
#      after such a flood joins the cluster's scene, and a SceneUpdate reaches every node;
#   4. the signed value of an older version put again is refused on every node (it follows an
#      older version, and the bus stores it after its write's deadline);
#   5. the bus frozen (SIGSTOP) during a SceneUpdate and thawed (SIGCONT) while its writer waits
#      to look: it is refused, the copy the bus then stores is taken by no node, and the next
#      update reaches every node;
#   5b. the key deleted (a delete marker, as any NATS client may put): a node puts the scene
#      back, and every node takes it as the same scene under a new version, rebuilding nothing;
#   5c. a signed scene no node can serve, an unsigned value on top: a node started then takes the
#      cluster's version, and a push through it reaches every node;
#   6. a healthy headset is served at the end, the version equal on every node.
set -euo pipefail
bin="$1"
source "$(dirname "$0")/cluster_lib.sh"
(umask 077 && echo "attack-test-token" > "$dir/token" && echo "attack-test-admin" > "$dir/admin" &&
  echo "node-password-$RANDOM$RANDOM" > "$dir/bus-password")
np=$(free_port)
url="nats://127.0.0.1:$np"
# The account of docs/CLUSTER.md: node users may publish only the scene subjects.
cat > "$dir/nats.conf" <<EOF
listen: 127.0.0.1:$np
jetstream { store_dir: "$dir/js" }
authorization {
  users = [
    { user: node, password: "$(cat "$dir/bus-password")", permissions: {
        publish: { allow: ["\$KV.hysar.scene", "node.*", "\$JS.API.INFO", "\$JS.API.STREAM.NAMES",
                           "\$JS.API.STREAM.INFO.KV_hysar", "\$JS.API.STREAM.CREATE.KV_hysar",
                           "\$JS.API.STREAM.PURGE.KV_hysar",
                           "\$JS.API.STREAM.MSG.GET.KV_hysar", "\$JS.API.DIRECT.GET.KV_hysar",
                           "\$JS.API.DIRECT.GET.KV_hysar.>",
                           "\$JS.API.CONSUMER.CREATE.KV_hysar", "\$JS.API.CONSUMER.CREATE.KV_hysar.>",
                           "\$JS.API.CONSUMER.DELETE.KV_hysar.>", "\$JS.FC.KV_hysar.>",
                           "\$JS.ACK.KV_hysar.>"] }
        subscribe: { allow: ["_INBOX.>", "node.*"] } } }
    { user: intruder, password: "open" }
  ]
}
EOF
nats-server -c "$dir/nats.conf" > "$dir/nats.log" 2>&1 &
nats=$!
servers+=($nats)
nats_ready "$dir/nats.log"
node_flags=(--cluster-user node --cluster-password-file "$dir/bus-password")
# NATS as an intruder: puts each of the files or literal values given on the scene subject.
intrude() {
  python3 - "$np" "$@" <<'PY'
import socket, sys
s = socket.create_connection(("127.0.0.1", int(sys.argv[1])), timeout=20)
s.sendall(b'CONNECT {"verbose":false,"pedantic":false,"user":"intruder","pass":"open"}\r\n')
for v in sys.argv[2:]:
    data = open(v[1:], "rb").read() if v.startswith("@") else v.encode()
    s.sendall(b"PUB $KV.hysar.scene %d\r\n" % len(data) + data + b"\r\n")
s.sendall(b"PING\r\n")
buf = b""
while b"PONG" not in buf:
    buf += s.recv(4096)
assert b"-ERR" not in buf, buf
PY
}
# The raw value of the scene subject's newest message (as an intruder may read it).
raw_latest() {
  python3 - "$np" <<'PY'
import base64, json, socket, sys
s = socket.create_connection(("127.0.0.1", int(sys.argv[1])), timeout=10)
s.sendall(b'CONNECT {"verbose":false,"pedantic":false,"user":"intruder","pass":"open"}\r\n'
          b"SUB _INBOX.raw 1\r\n")
req = json.dumps({"last_by_subj": "$KV.hysar.scene"}).encode()
s.sendall(b"PUB $JS.API.STREAM.MSG.GET.KV_hysar _INBOX.raw %d\r\n" % len(req) + req + b"\r\n")
f = s.makefile("rb")
while True:
    line = f.readline().decode().strip()
    if line.startswith("MSG"):
        body = json.loads(f.read(int(line.split()[-1]) + 2)[:-2])
        sys.stdout.buffer.write(base64.b64decode(body["message"]["data"]))
        break
PY
}
frames() {  # headset layers node b has sent
  "$bin/hysar" admin --connect "127.0.0.1:$port_b" --token-file "$dir/admin" stats --json \
    | python3 -c "import json,sys; print(sum(v.get('frames',0) for v in json.load(sys.stdin).get('viewers',[])))"
}

start_node a --admin-listen 0
start_node b
password=$(cat "$dir/bus-password")
# 0. The password is in no log and in no command line.
! grep -q "$password" "$dir"/node-*.log || fail "a node printed the bus password"
! ps -eo args | grep -v grep | grep -q "$password" || fail "the bus password is on a command line"
grep -q "^cluster: node 'a' on $url, scene version 1$" "$dir/node-a.log" \
  || fail "node a did not put version 1: $(grep cluster "$dir/node-a.log")"
admin_port=$(grep -oE "admin endpoint on http://127.0.0.1:[0-9]+" "$dir/node-a.log" | grep -oE "[0-9]+$")
"$bin/clients/hysar-loadgen" --connect "127.0.0.1:$port_b" --token-file "$dir/token" --viewers 2 \
  --rate 10 --seconds 0 --scale 0.2 > "$dir/loadgen.log" 2>&1 &
pids+=($!)
push a first > "$dir/push.log" 2>&1 || fail "push through a: $(cat "$dir/push.log")"
within 10 'same_everywhere 2 a b' || fail "version 2 not on both nodes: a: $(applied a); b: $(applied b)"
echo "0. two nodes on a bus with user/password from a file; version 2 on both; no password shown"

# 1. An unsigned scene, put by a plain NATS client: no node applies it.
sed 's/"name": "HySAR experiment 1 room[^"]*"/"name": "defaced"/' "$src/configs/exp1-room.json" > "$dir/evil.json"
intrude "@$dir/evil.json"
sleep 1.5
same_everywhere 2 a b || fail "an unsigned value was applied: a: $(applied a); b: $(applied b)"
! grep -q "defaced" "$dir"/node-*.log || fail "a node served the unsigned scene"
grep -q "not signed with the admin credential" "$dir/node-a.log" || fail "node a did not log the unsigned value"
echo "1. an unsigned scene on the bus: ignored by both nodes (still version 2)"

ignored() {  # WHY: node a's count of bus values ignored for that reason
  curl -sf -H "Authorization: Bearer $(cat "$dir/token")" "http://127.0.0.1:$admin_port/metrics" \
    | grep -E "^hysar_scene_bus_ignored_values_total\{why=\"$1\"\}" | awk '{print $2}'
}
# 2. Poison values: a new node still starts, on the cluster's scene. One is unsigned; the other is
# signed with the admin credential (a tool that signs without checking could write it) but is no
# scene document, and every node refuses it alike.
intrude "{{{"
signed_poison() {  # BASE JSON: a value signed as a node signs one
  python3 - "$(cat "$dir/admin")" "$1" "$2" <<'PY'
import hashlib, hmac, sys, time
token, base, body = sys.argv[1], sys.argv[2], sys.argv[3]
deadline = int(time.time() * 1000) + 5000
key = hashlib.sha256(("hysar scene bus key\n" + token).encode()).digest()
mac = hmac.new(key, f"hysar-scene 1\n{base}\n{deadline}\n{body}".encode(), hashlib.sha256).hexdigest()
sys.stdout.write(f"hysar-scene 1 {base} {deadline} {mac}\n{body}")
PY
}
signed_poison 2 '{"name": "signed poison", "prop": 42}' > "$dir/poison.value"
intrude "@$dir/poison.value"
within 10 '(( $(ignored invalid) >= 1 ))' || fail "node a did not count the signed poison as invalid"
# The nodes put the scene they serve back over the signed poison (above its revision, which
# they took as their version), each taking it as the same scene.
within 10 'grep -q "with a scene on top that this node cannot serve" "$dir"/node-*.log' \
  || fail "no node put its scene back over the signed poison"
within 10 'v=$(last_applied a); (( v > 3 )) && same_everywhere $v a b' \
  || fail "the nodes did not take the scene put back: a: $(applied a); b: $(applied b)"
! grep -q "'signed poison'" "$dir"/node-*.log || fail "a node served the signed poison"
start_node c
grep -q "^cluster: serving the bus's scene 'room first'" "$dir/node-c.log" \
  || fail "node c did not start on the cluster's scene: $(grep -E 'cluster|error' "$dir/node-c.log")"
within 10 'v=$(last_applied a); same_everywhere $v a b c' \
  || fail "the versions differ: a: $(applied a); b: $(applied b); c: $(applied c)"
back=$(last_applied a)
push c after-poison > "$dir/push.log" 2>&1 || fail "push after the poison: $(cat "$dir/push.log")"
want=$(grep -oE "applied: scene version [0-9]+" "$dir/push.log" | grep -oE "[0-9]+$")
within 10 'same_everywhere $want a b c' || fail "version $want not on every node: a: $(applied a); b: $(applied b); c: $(applied c)"
echo "2. '{{{' and a signed value that is no scene on the bus: no node applies them (node a counts $(ignored invalid) invalid); version 2's scene put back as v$back; a new node starts on it; the next push, v$want, on a, b, c"

# 3. A flood of 2,000 unsigned values while headsets stream; then an update reaches every node.
within 20 '(( $(frames) > 20 ))' || fail "the headsets got no layers"
fb=$(frames); tb=$(date +%s%N); sleep 2
f0=$(frames); t0=$(date +%s%N)
before_rate=$(( (f0 - fb) * 1000000000 / (t0 - tb) ))
flood=()
for i in $(seq 2000); do flood+=("{\"name\":\"flood $i\"}"); done
intrude "${flood[@]}"
sleep 2
f1=$(frames); t1=$(date +%s%N)
rate=$(( (f1 - f0) * 1000000000 / (t1 - t0) ))
(( rate >= 5 && rate * 2 >= before_rate )) \
  || fail "headsets starved during the flood: $before_rate layers/s before, $rate during"
# The flood pushed every signed value out of the key's history: a node puts the cluster's scene
# back on top (the same scene, relabelled), and the nodes converge on it.
within 10 'grep -q "with no signed value left" "$dir"/node-*.log' \
  || fail "no node put the scene back after the flood"
within 10 'v=$(last_applied a); same_everywhere $v a b c' \
  || fail "the nodes differ after the flood: a: $(applied a); b: $(applied b); c: $(applied c)"
! grep -q "'flood" "$dir"/node-*.log || fail "a node served a flooded value"
# A node started while the key holds only unsigned values joins the cluster's scene: it waits
# for a running node to put it back (or finds it back already), rather than putting its own.
flood=()
for i in $(seq 100); do flood+=("{\"name\":\"flood again $i\"}"); done
intrude "${flood[@]}"
start_node d
grep -q "^cluster: serving the bus's scene 'room after-poison'" "$dir/node-d.log" \
  || fail "node d did not join the cluster's scene after a flood: $(grep -E 'cluster|scene bus|error' "$dir/node-d.log")"
waited=$(grep -c "waiting up to 6 s for a running node" "$dir/node-d.log" || true)
within 10 'v=$(last_applied a); same_everywhere $v a b c d' \
  || fail "the nodes differ after node d started: a: $(applied a); b: $(applied b); c: $(applied c); d: $(applied d)"
unsigned_count() { ignored unsigned; }
# The bucket keeps 16 values of the key: a flood faster than the watch is partly dropped by the
# bus itself before any node sees it; every value a node sees is counted.
within 10 '(( $(unsigned_count) >= 16 ))' || fail "/metrics counts $(unsigned_count) unsigned values, expected >= 16"
unsigned=$(unsigned_count)
push b after-flood > "$dir/push.log" 2>&1 || fail "push after the flood: $(cat "$dir/push.log")"
want=$(grep -oE "applied: scene version [0-9]+" "$dir/push.log" | grep -oE "[0-9]+$")
within 10 'same_everywhere $want a b c d' || fail "version $want not on every node: a: $(applied a); b: $(applied b); c: $(applied c); d: $(applied d)"
echo "3. 2,000 unsigned values: headsets at $rate layers/s ($before_rate before), $unsigned seen and counted in /metrics; node d, started after a flood, joined (it waited: $waited); v$want on a, b, c, d"

# 4. An old signed value put again (a replay) is refused.
old=$(raw_latest > "$dir/old.value" && echo ok) || fail "cannot read the bus's value"
push a newer > "$dir/push.log" 2>&1 || fail "push: $(cat "$dir/push.log")"
want=$(grep -oE "applied: scene version [0-9]+" "$dir/push.log" | grep -oE "[0-9]+$")
within 10 'same_everywhere $want a b c' || fail "version $want not on every node"
intrude "@$dir/old.value"
sleep 1.5
same_everywhere "$want" a b c || fail "a replayed value was applied: a: $(applied a); b: $(applied b); c: $(applied c)"
# Refused as following an older version (replayed), or, put again more than 2 s after its write,
# as stored past its deadline (late, which is checked first).
(( $(ignored late) + $(ignored replayed) >= 1 )) || fail "node a did not count the replay"
echo "4. the signed value of an older version put again: refused on every node (still v$want)"

# 5. The bus frozen during a push: refused, and the copy stored after the thaw lands nowhere.
before=$want
kill -STOP "$nats"
push a frozen > "$dir/push-frozen.txt" 2>&1 &
push_pid=$!
# Past the write's deadline and the clock margin: the writer is looking whether the bus stored
# it, and keeps asking while the bus does not answer; thawed, the bus stores the copy late and
# answers, and the writer refuses for good.
sleep 6
if ! kill -0 "$push_pid" 2>/dev/null; then
  kill -CONT "$nats"; fail "the writer answered while the bus was frozen: $(cat "$dir/push-frozen.txt")"
fi
kill -CONT "$nats"
if wait "$push_pid"; then fail "a push to a frozen bus was taken: $(cat "$dir/push-frozen.txt")"; fi
out=$(cat "$dir/push-frozen.txt")
grep -q "stays refused" <<< "$out" || fail "the push to a frozen bus: $out"
sleep 3
same_everywhere "$before" a b c || fail "the refused update landed: a: $(applied a); b: $(applied b); c: $(applied c)"
! grep -q "'room frozen'" "$dir"/node-*.log || fail "a node served the refused scene"
# (Whether the bus stored the copy after the thaw depends on the connection surviving the
# freeze; if it did, node a counts it as late.)
late=$(ignored late)
# The first push right after the thaw may still get a conflict naming the late copy's revision
# (not yet seen by that node); the admin's retry goes through.
within 15 'push b thawed > "$dir/push.log" 2>&1' || fail "push after the thaw: $(cat "$dir/push.log")"
want=$(grep -oE "applied: scene version [0-9]+" "$dir/push.log" | grep -oE "[0-9]+$")
within 10 'same_everywhere $want a b c' || fail "version $want not on every node: a: $(applied a); b: $(applied b); c: $(applied c)"
echo "5. a push while the bus was frozen: refused ($(grep -oE 'did not confirm[^;]*' <<< "$out")); after the thaw no node took it (node a counts $late late values); v$want on a, b, c"

# 5b. A delete marker on the key: the bus found empty is refilled with the scene every node
# holds; they relabel it as the new version and render nothing again.
metric() {  # NAME: node a's /metrics sample
  curl -sf -H "Authorization: Bearer $(cat "$dir/token")" "http://127.0.0.1:$admin_port/metrics" \
    | grep -E "^$1 " | awk '{print $2}'
}
renders=$(metric hysar_projector_renders_total)
python3 - "$np" <<'PY'
import socket, sys
s = socket.create_connection(("127.0.0.1", int(sys.argv[1])), timeout=10)
s.sendall(b'CONNECT {"verbose":false,"pedantic":false,"headers":true,"user":"intruder","pass":"open"}\r\n')
hdr = b"NATS/1.0\r\nKV-Operation: DEL\r\n\r\n"
s.sendall(b"HPUB $KV.hysar.scene %d %d\r\n" % (len(hdr), len(hdr)) + hdr + b"\r\nPING\r\n")
buf = b""
while b"PONG" not in buf:
    buf += s.recv(4096)
assert b"-ERR" not in buf, buf
PY
deleted=$want
within 15 '(( $(last_applied a) > deleted )) && same_everywhere $(last_applied a) a b c' \
  || fail "the nodes did not converge on a refilled version after the delete: a: $(applied a); b: $(applied b); c: $(applied c)"
want=$(last_applied a)
for n in a b c; do
  grep -q "scene version $want: '.*' (the same scene again: relabelled, not rebuilt)" "$dir/node-$n.log" \
    || fail "node $n did not relabel version $want: $(grep -E "scene version $want" "$dir/node-$n.log")"
done
[[ "$(metric hysar_projector_renders_total)" == "$renders" ]] \
  || fail "node a rendered again for the refill: $renders -> $(metric hysar_projector_renders_total)"
(( $(metric hysar_scene_relabels_total) >= 1 )) || fail "node a counts no relabel"
echo "5b. the key deleted: refilled as v$want, relabelled on a, b and c with no render (node a: $renders projector renders before and after)"

# 5c. A scene signed with the admin credential that no node can serve (its glTF is missing on
# every node), then an unsigned value on top of it: every node holds it and takes its version;
# a node started now serves the last scene it can but takes that version too, so that a push
# through it follows the cluster's and reaches every node.
python3 -c 'import json, sys; d = json.load(open(sys.argv[1])); d["name"] = "room unservable"
d["prop"] = {"kind": "gltf", "gltf": "missing-everywhere.glb"}; print(json.dumps(d))' \
  "$src/configs/exp1-room.json" > "$dir/unservable.json"
signed_poison "$want" "$(cat "$dir/unservable.json")" > "$dir/unservable.value"
intrude "@$dir/unservable.value"
within 10 'grep -q "cannot be served here.*missing-everywhere" "$dir/node-a.log"' \
  || fail "node a did not refuse the scene it cannot serve"
intrude '{"name": "on top"}'
start_node e
grep -q "the cluster's scene, version [0-9]*, cannot be served here" "$dir/node-e.log" \
  || fail "node e did not take the cluster's version: $(grep -E 'cluster|scene bus' "$dir/node-e.log")"
push e after-unservable > "$dir/push.log" 2>&1 || fail "push through e: $(cat "$dir/push.log")"
want=$(grep -oE "applied: scene version [0-9]+" "$dir/push.log" | grep -oE "[0-9]+$")
within 10 'same_everywhere $want a b c d e' \
  || fail "version $want not on every node: a: $(applied a); b: $(applied b); c: $(applied c); d: $(applied d); e: $(applied e)"
echo "5c. a signed scene no node can serve, an unsigned value on top: node e started on the last scene it serves at the cluster's version; its push, v$want, on a, b, c, d, e"

# 6. A healthy headset at the end, served the version every node holds.
mkdir "$dir/p"
"$bin/clients/hysar-projector" --connect "127.0.0.1:$port_c" --token-file "$dir/token" --frames 1 \
  --out "$dir/p" > "$dir/projector.log" 2>&1 || fail "projector on node c"
[[ -e "$dir/p/projector_v$want.png" ]] || fail "the projector frame is not v$want: $(ls "$dir/p")"
f2=$(frames); sleep 1; (( $(frames) > f2 )) || fail "the headsets stopped getting layers"
echo "6. headsets served, the projector on v$want; a: $(applied a); b: $(applied b); c: $(applied c)"
