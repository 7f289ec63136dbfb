#!/usr/bin/env bash
# hysar-hmd driven by live poses (clients/common/pose_input.hpp): from standard input and from a UDP
# port on loopback. Checks that the layers it receives follow those poses (each is, byte for
# byte, the layer the same pose gets from a --csv trajectory; the two poses give different ones), that bad
# and out-of-order lines are reported and skipped, and that a silent source is reported stale.
# Usage: pose_input_test.sh BUILD_DIR SOURCE_DIR
set -uo pipefail
build=$1 src=$2
hysar=$build/hysar hmd=$build/clients/hysar-hmd
dir=$(mktemp -d)
server=
cleanup() { [[ -n $server ]] && kill -KILL "$server" 2>/dev/null; rm -rf "$dir"; }
trap cleanup EXIT
fail() { echo "pose_input: FAIL: $*"; for f in "$dir"/*.log; do sed "s|^|  $(basename "$f"): |" "$f"; done; exit 1; }

sed -e 's/"width": *1920, *"height": *1200, *"fx": *3000, *"fy": *3000, *"cx": *959.5, *"cy": *599.5/"width": 480, "height": 300, "fx": 750, "fy": 750, "cx": 239.5, "cy": 149.5/' \
  "$src/configs/exp1-room.json" > "$dir/room.json"
(umask 077 && printf 'secret\n' > "$dir/token")
"$hysar" serve --scene "$dir/room.json" --listen 127.0.0.1:0 --token-file "$dir/token" > "$dir/serve.log" 2>&1 &
server=$!
for _ in $(seq 200); do grep -q "serving" "$dir/serve.log" && break; sleep 0.1; done
port=$(sed -n 's/.* on 127\.0\.0\.1:\([0-9]*\).*/\1/p' "$dir/serve.log" | head -1)
[[ -n $port ]] || fail "the server did not start"
# The scene's warm-up runs after the server listens: until it is done a first pose can wait
# past the trajectory's second one and be superseded (latest pose wins).
for _ in $(seq 600); do grep -q "warm-up" "$dir/serve.log" && break; sleep 0.1; done
common=(--connect "127.0.0.1:$port" --token-file "$dir/token" --scale 0.25 --format rgba8 --encoding raw)

# Two poses looking at the dome from 0.8 m: from +z, and from 30 deg to the side (look_at).
pose1="0,1.1,0.8,0.978275772,-0.207307774,0,0"
pose2="0.4,1.1,0.692820323,0.944941834,-0.200243933,0.253196401,0.0536552"
# The reference: the same poses as a --csv trajectory.
printf '0,%s\n1,%s\n' "$pose1" "$pose2" > "$dir/poses.csv"
"$hmd" "${common[@]}" --csv "$dir/poses.csv" --out "$dir/csv" --name ref > "$dir/csv.log" 2>&1 ||
  fail "the --csv run failed"
[[ -f $dir/csv/ref_csv1_right.png && -f $dir/csv/ref_csv2_right.png ]] || fail "the --csv run wrote no layers"

check_follows() { # DIR NAME: the layers for frame ids 1 and 2 equal the --csv ones and differ
  for id in 1 2; do
    for eye in left right; do
      f="$1/$2_f${id}_$eye.png"
      [[ -f $f ]] || fail "$2: no layer for frame_id $id ($eye)"
      cmp -s "$f" "$dir/csv/ref_csv${id}_$eye.png" ||
        fail "$2: the layer for frame_id $id ($eye) is not the one its pose gets"
    done
  done
  cmp -s "$1/$2_f1_right.png" "$1/$2_f2_right.png" && fail "$2: both poses gave the same layer"
  return 0
}

# Standard input: a comment, a bad line, a pose, an out-of-order line, a pose; a second between
# them so that neither is superseded.
{
  echo "# t_s,x,y,z,qw,qx,qy,qz,frame_id"
  echo "10,1,2,three,1,0,0,0"
  sleep 1; echo "10 ${pose1//,/ } 1"
  sleep 1; echo "5,$pose1,9"
  echo "11,$pose2,2"
  sleep 1
} | "$hmd" "${common[@]}" --poses - --out "$dir/stdin" --name stdin --summary "$dir/stdin.json" \
  > "$dir/stdin.log" 2>&1 || fail "hysar-hmd --poses - failed"
check_follows "$dir/stdin" stdin
grep -q "standard input line 2: item 4: 'three' is not a number" "$dir/stdin.log" || fail "the bad line was not reported"
grep -q "line 4: t_s 5 is older than the newest pose's 10 (out of order, skipped)" "$dir/stdin.log" ||
  fail "the out-of-order line was not reported"
grep -q '"bad_lines": 1' "$dir/stdin.json" || fail "summary: bad_lines"
grep -q '"out_of_order": 1' "$dir/stdin.json" || fail "summary: out_of_order"

# UDP: two datagrams, then silence (reported stale), then --frames 2 ends the run.
"$hmd" "${common[@]}" --poses udp:0 --frames 2 --stale-ms 300 --out "$dir/udp" --name udp \
  > "$dir/udp.log" 2>&1 &
hmd_pid=$!
for _ in $(seq 100); do grep -q "following poses" "$dir/udp.log" && break; sleep 0.1; done
udp_port=$(sed -n 's/.*following poses from UDP 127\.0\.0\.1:\([0-9]*\).*/\1/p' "$dir/udp.log")
[[ -n $udp_port && $udp_port != 0 ]] || fail "hysar-hmd did not name the UDP port it bound"
sleep 0.3
printf '1,%s,1\n' "$pose1" > "/dev/udp/127.0.0.1/$udp_port"
sleep 1.5
printf 'garbage\n2,%s,2\n' "$pose2" > "/dev/udp/127.0.0.1/$udp_port"
for _ in $(seq 150); do kill -0 "$hmd_pid" 2>/dev/null || break; sleep 0.1; done
if kill -0 "$hmd_pid" 2>/dev/null; then kill "$hmd_pid"; fail "hysar-hmd --poses udp did not stop after --frames 2"; fi
wait "$hmd_pid" || fail "hysar-hmd --poses udp failed"
check_follows "$dir/udp" udp
grep -q "is stale: no pose for" "$dir/udp.log" || fail "the silent UDP source was not reported stale"
grep -q "line 2: .*garbage" "$dir/udp.log" || fail "the bad UDP line was not reported"
echo "pose_input: ok (stdin and UDP poses followed; bad, out-of-order and stale reported)"
