#!/usr/bin/env bash
# Bad arguments and unreachable or unwilling servers for hysar-hmd, hysar-projector and
# hysar-loadgen: each case must exit with status 2, say on stderr which option or value is at
# fault, and never abort. No hysar server is needed: the network cases use a loopback port
# that was just closed, and (where python3 is present) a small fake server on loopback that
# closes at once, answers with an Error, or sends bytes that are not a frame.
# Usage: clients_bad_args.sh BUILD_DIR
set -u
case_lib="$(cd "$(dirname "$0")" && pwd)/case_lib.sh"
build="$1"
hmd="$build/clients/hysar-hmd"
projector="$build/clients/hysar-projector"
loadgen="$build/clients/hysar-loadgen"
work="$build/tests/clients_bad_args"
rm -rf "$work" && mkdir -p "$work"
cd "$work" || exit 1

source "$case_lib"
# expect_usage NAME PATTERN COMMAND...: COMMAND exits 2, its stderr is not empty and matches
# PATTERN (grep -E), and nothing in its output speaks of an abort or an internal error.
expect_usage() {
  local name="$1" pattern="$2"
  shift 2
  expect "$name" 2 err "$pattern" "$@"
}

# A port nobody listens on: bound and closed again (python3), else port 1.
closed_port=1
if command -v python3 > /dev/null; then
  closed_port=$(python3 -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1]); s.close()')
fi
dead="127.0.0.1:$closed_port"

printf 'good-token\n' > token
printf 'good-token\r\n' > token_crlf
: > token_empty
printf '\r\n' > token_blank
mkdir -p a_folder
printf 'not a folder' > a_file

# Headset profiles and pose files with one thing wrong each.
printf '{"eye_width": 64, "eye_height": 40, "fov_x_deg": 60, "fov_y_deg": 40}\n' > profile_ok.json
printf '{"eye_width": 64, "eye_height": ' > profile_not_json.json
printf '{"eye_height": 40, "fov_x_deg": 60, "fov_y_deg": 40}\n' > profile_no_width.json
printf '{"eye_width": "wide", "eye_height": 40, "fov_x_deg": 60, "fov_y_deg": 40}\n' > profile_text_width.json
printf '{"eye_width": 1e300, "eye_height": 40, "fov_x_deg": 60, "fov_y_deg": 40}\n' > profile_huge.json
printf '{"eye_width": 64, "eye_height": 40, "fov_x_deg": 180, "fov_y_deg": 40}\n' > profile_fov.json
printf '[1, 2, 3]\n' > profile_array.json
printf 't_s,x,y,z,qw,qx,qy,qz\n0,0,1.1,0.8,1,0,0,0\n0.1,0,1.1,0.8,1,0,0,0\n' > poses_ok.csv
printf '0,0,1.1,0.8,1,0,0,0\n0.1,0,abc,0.8,1,0,0,0\n' > poses_text.csv
printf '0,0,1.1,0.8,1,0,0,0\n0.1,0,nan,0.8,1,0,0,0\n' > poses_nan.csv
printf '0,0,1.1,0.8,1,0,0\n' > poses_short.csv
printf '0,0,1.1,0.8,1,0,0,0,9\n' > poses_long.csv
printf '0,0,1.1,0.8,2,0,0,0\n' > poses_quaternion.csv
printf -- '-1,0,1.1,0.8,1,0,0,0\n' > poses_negative_time.csv
printf '1,0,1.1,0.8,1,0,0,0\n0.5,0,1.1,0.8,1,0,0,0\n' > poses_backwards.csv
printf '0,0,1e999,0.8,1,0,0,0\n' > poses_overflow.csv
printf '# nothing but a comment\n' > poses_empty.csv

T=(--token-file token --connect "$dead")

# Where hmd and projector write (loadgen writes nothing but --json).
out_for() {
  out_args=()
  [ "$1" = loadgen ] || out_args=(--out "out_$1")
}

for client in hmd projector loadgen; do
  bin="$build/clients/hysar-$client"
  out_for "$client"
  # Options and values every client has.
  expect_usage "$client unknown option" "'--bogus'" "$bin" "${T[@]}" --bogus
  expect_usage "$client stray argument" "'stray'" "$bin" "${T[@]}" stray
  expect_usage "$client option without its value" "--connect" "$bin" "${T[@]}" --connect
  expect_usage "$client no token" "--token" "$bin" --connect "$dead"
  expect_usage "$client empty --token" "--token" "$bin" --token "" --connect "$dead"
  expect_usage "$client --token and --token-file" "--token.*--token-file" "$bin" --token x --token-file token
  expect_usage "$client missing --token-file" "--token-file 'nowhere'" "$bin" --token-file nowhere
  expect_usage "$client empty --token-file" "--token-file 'token_empty'" "$bin" --token-file token_empty
  expect_usage "$client blank CRLF --token-file" "--token-file 'token_blank'" "$bin" --token-file token_blank
  expect_usage "$client folder as --token-file" "--token-file 'a_folder'" "$bin" --token-file a_folder
  expect_usage "$client token over 256 bytes" "--token.*256" "$bin" --token "$(printf 'x%.0s' $(seq 300))"
  expect_usage "$client address without a port" "--connect 'localhost'.*port" "$bin" "${T[@]}" --connect localhost
  expect_usage "$client port 0" "--connect '127.0.0.1:0'" "$bin" "${T[@]}" --connect 127.0.0.1:0
  expect_usage "$client port 70000" "--connect '127.0.0.1:70000'" "$bin" "${T[@]}" --connect 127.0.0.1:70000
  expect_usage "$client port not a number" "--connect '127.0.0.1:http'" "$bin" "${T[@]}" --connect 127.0.0.1:http
  expect_usage "$client empty port" "--connect '127.0.0.1:'" "$bin" "${T[@]}" --connect 127.0.0.1:
  expect_usage "$client no host" "--connect ':7700'" "$bin" "${T[@]}" --connect :7700
  expect_usage "$client IPv6 without brackets" "--connect '::1:7700'" "$bin" "${T[@]}" --connect ::1:7700
  expect_usage "$client empty unix path" "--connect 'unix:'" "$bin" "${T[@]}" --connect unix:
  expect_usage "$client unix socket not there" "unix:$work/no.sock" "$bin" "${T[@]}" --connect "unix:$work/no.sock" "${out_args[@]}"
  expect_usage "$client closed port" "$dead" "$bin" "${T[@]}" --connect "$dead" "${out_args[@]}"
done

# hysar-hmd
expect_usage "hmd --angles abc" "--angles 'abc'" "$hmd" "${T[@]}" --angles abc
expect_usage "hmd --angles 1e999" "--angles '1e999'" "$hmd" "${T[@]}" --angles 1e999
expect_usage "hmd --angles nan" "--angles 'nan'" "$hmd" "${T[@]}" --angles nan
expect_usage "hmd --angles inf" "--angles '0,inf'" "$hmd" "${T[@]}" --angles 0,inf
expect_usage "hmd --angles empty" "--angles ''" "$hmd" "${T[@]}" --angles ""
expect_usage "hmd --angles empty item" "--angles '1,,2'" "$hmd" "${T[@]}" --angles 1,,2
expect_usage "hmd --angles trailing comma" "--angles '10,'" "$hmd" "${T[@]}" --angles 10,
expect_usage "hmd --angles 12abc" "--angles '12abc'" "$hmd" "${T[@]}" --angles 12abc
expect_usage "hmd --angles out of range" "--angles '720'" "$hmd" "${T[@]}" --angles 720
expect_usage "hmd --target a,b,c" "--target 'a,b,c'" "$hmd" "${T[@]}" --target a,b,c
expect_usage "hmd --target two numbers" "--target '1,2'" "$hmd" "${T[@]}" --target 1,2
expect_usage "hmd --target four numbers" "--target '1,2,3,4'" "$hmd" "${T[@]}" --target 1,2,3,4
expect_usage "hmd --target 1e999" "--target '1e999,0,0'" "$hmd" "${T[@]}" --target 1e999,0,0
expect_usage "hmd --scale abc" "--scale.*'abc'" "$hmd" "${T[@]}" --scale abc
expect_usage "hmd --scale 0" "--scale.*'0'" "$hmd" "${T[@]}" --scale 0
expect_usage "hmd --scale 1e999" "--scale.*'1e999'" "$hmd" "${T[@]}" --scale 1e999
expect_usage "hmd --distance -1" "--distance.*'-1'" "$hmd" "${T[@]}" --distance -1
expect_usage "hmd --height nan" "--height.*'nan'" "$hmd" "${T[@]}" --height nan
expect_usage "hmd --height ' 1'" "--height.*' 1'" "$hmd" "${T[@]}" --height " 1"
expect_usage "hmd --orbit 0" "--orbit.*'0'" "$hmd" "${T[@]}" --orbit 0
expect_usage "hmd --orbit abc" "--orbit.*'abc'" "$hmd" "${T[@]}" --orbit abc
expect_usage "hmd --format" "--format.*'bgr'" "$hmd" "${T[@]}" --format bgr
expect_usage "hmd --encoding" "--encoding.*'zip'" "$hmd" "${T[@]}" --encoding zip
expect_usage "hmd empty --name" "--name" "$hmd" "${T[@]}" --name ""
expect_usage "hmd --name over 64 bytes" "--name.*64" "$hmd" "${T[@]}" --name "$(printf 'n%.0s' $(seq 80))"
expect_usage "hmd --name with a slash" "--name 'a/b'" "$hmd" "${T[@]}" --name a/b
expect_usage "hmd two trajectories" "--angles.*--orbit" "$hmd" "${T[@]}" --angles 0 --orbit 5
expect_usage "hmd missing --profile" "--profile 'nowhere.json'" "$hmd" "${T[@]}" --profile nowhere.json
expect_usage "hmd folder as --profile" "--profile 'a_folder'" "$hmd" "${T[@]}" --profile a_folder
expect_usage "hmd --profile not JSON" "--profile 'profile_not_json.json'" "$hmd" "${T[@]}" --profile profile_not_json.json
expect_usage "hmd --profile without eye_width" "--profile 'profile_no_width.json'.*eye_width" "$hmd" "${T[@]}" --profile profile_no_width.json
expect_usage "hmd --profile text eye_width" "--profile 'profile_text_width.json'.*eye_width" "$hmd" "${T[@]}" --profile profile_text_width.json
expect_usage "hmd --profile huge eye_width" "--profile 'profile_huge.json'.*eye_width" "$hmd" "${T[@]}" --profile profile_huge.json
expect_usage "hmd --profile fov 180" "--profile 'profile_fov.json'.*fov_x_deg" "$hmd" "${T[@]}" --profile profile_fov.json
expect_usage "hmd --profile array" "--profile 'profile_array.json'" "$hmd" "${T[@]}" --profile profile_array.json
expect_usage "hmd missing --csv" "--csv 'nowhere.csv'" "$hmd" "${T[@]}" --csv nowhere.csv
expect_usage "hmd --csv text" "--csv 'poses_text.csv' line 2.*'abc'" "$hmd" "${T[@]}" --csv poses_text.csv
expect_usage "hmd --csv NaN" "--csv 'poses_nan.csv' line 2.*'nan'" "$hmd" "${T[@]}" --csv poses_nan.csv
expect_usage "hmd --csv 7 columns" "--csv 'poses_short.csv' line 1" "$hmd" "${T[@]}" --csv poses_short.csv
expect_usage "hmd --csv 9 columns" "--csv 'poses_long.csv' line 1" "$hmd" "${T[@]}" --csv poses_long.csv
expect_usage "hmd --csv quaternion" "--csv 'poses_quaternion.csv' line 1.*quaternion" "$hmd" "${T[@]}" --csv poses_quaternion.csv
expect_usage "hmd --csv negative time" "--csv 'poses_negative_time.csv' line 1" "$hmd" "${T[@]}" --csv poses_negative_time.csv
expect_usage "hmd --csv time backwards" "--csv 'poses_backwards.csv' line 2" "$hmd" "${T[@]}" --csv poses_backwards.csv
expect_usage "hmd --csv 1e999" "--csv 'poses_overflow.csv' line 1.*'1e999'" "$hmd" "${T[@]}" --csv poses_overflow.csv
expect_usage "hmd --csv no pose" "--csv 'poses_empty.csv'.*no pose" "$hmd" "${T[@]}" --csv poses_empty.csv
expect_usage "hmd --out is a file" "--out 'a_file'" "$hmd" "${T[@]}" --out a_file
expect_usage "hmd --summary folder missing" "--summary 'nowhere/s.json'" "$hmd" "${T[@]}" --summary nowhere/s.json
expect_usage "hmd good files, closed port" "$dead" "$hmd" "${T[@]}" --profile profile_ok.json --csv poses_ok.csv --connect "$dead" --out out_hmd

# hysar-projector
expect_usage "projector --frames -1" "--frames.*'-1'" "$projector" "${T[@]}" --frames -1
expect_usage "projector --frames 1.5" "--frames.*'1.5'" "$projector" "${T[@]}" --frames 1.5
expect_usage "projector --frames abc" "--frames.*'abc'" "$projector" "${T[@]}" --frames abc
expect_usage "projector --frames 1e99" "--frames.*'1e99'" "$projector" "${T[@]}" --frames 1e99
expect_usage "projector --frames huge" "--frames.*'99999999999999999999'" "$projector" "${T[@]}" --frames 99999999999999999999
expect_usage "projector --timeout 0" "--timeout.*'0'" "$projector" "${T[@]}" --timeout 0
expect_usage "projector --timeout inf" "--timeout.*'inf'" "$projector" "${T[@]}" --timeout inf
expect_usage "projector --monitor without --window" "--monitor.*--window" "$projector" "${T[@]}" --monitor 1
expect_usage "projector --monitor abc" "--monitor.*'abc'" "$projector" "${T[@]}" --window --monitor abc
expect_usage "projector --screenshot without --window" "--screenshot.*--window" "$projector" "${T[@]}" --screenshot s.png
expect_usage "projector empty --name" "--name" "$projector" "${T[@]}" --name ""
expect_usage "projector --out is a file" "--out 'a_file'" "$projector" "${T[@]}" --out a_file

# hysar-loadgen
expect_usage "loadgen --viewers 0" "--viewers.*'0'" "$loadgen" "${T[@]}" --viewers 0
expect_usage "loadgen --viewers 2.5" "--viewers.*'2.5'" "$loadgen" "${T[@]}" --viewers 2.5
expect_usage "loadgen --viewers 5000" "--viewers.*'5000'" "$loadgen" "${T[@]}" --viewers 5000
expect_usage "loadgen --rate abc" "--rate.*'abc'" "$loadgen" "${T[@]}" --rate abc
expect_usage "loadgen --rate 0" "--rate.*'0'" "$loadgen" "${T[@]}" --rate 0
expect_usage "loadgen --seconds -5" "--seconds.*'-5'" "$loadgen" "${T[@]}" --seconds -5
expect_usage "loadgen --seconds 1e999" "--seconds.*'1e999'" "$loadgen" "${T[@]}" --seconds 1e999
expect_usage "loadgen --scale nan" "--scale.*'nan'" "$loadgen" "${T[@]}" --scale nan
expect_usage "loadgen --format" "--format.*'rgb'" "$loadgen" "${T[@]}" --format rgb
expect_usage "loadgen --encoding" "--encoding.*'gzip'" "$loadgen" "${T[@]}" --encoding gzip
expect_usage "loadgen missing --profile" "--profile 'nowhere.json'" "$loadgen" "${T[@]}" --profile nowhere.json
expect_usage "loadgen --profile not JSON" "--profile 'profile_not_json.json'" "$loadgen" "${T[@]}" --profile profile_not_json.json
expect_usage "loadgen --json folder missing" "--json 'nowhere/r.json'" "$loadgen" "${T[@]}" --json nowhere/r.json
expect_usage "loadgen --json is a folder" "--json 'a_folder'" "$loadgen" "${T[@]}" --json a_folder

# Servers that will not give a session: one that closes at once, one that answers Hello with
# an Error, one that sends bytes that are not a frame. The last also checks the token it was
# sent: a CRLF token file must give the same token as an LF one.
if command -v python3 > /dev/null; then
  cat > fake_server.py << 'EOF'
import socket, struct, sys, time

mode, port_file = sys.argv[1], sys.argv[2]
srv = socket.socket()
srv.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
srv.bind(("127.0.0.1", 0))
srv.listen(16)
srv.settimeout(120)
with open(port_file + ".tmp", "w") as f:
    f.write(str(srv.getsockname()[1]))
import os
os.rename(port_file + ".tmp", port_file)

def read_exact(c, n):
    b = b""
    while len(b) < n:
        chunk = c.recv(n - len(b))
        if not chunk:
            return None
        b += chunk
    return b

def error_frame(code, text, seq):
    msg = text.encode()
    payload = struct.pack("<HH", code, len(msg)) + msg
    return struct.pack("<IHHII", 0x52535948, 1, 13, len(payload), seq) + payload

while True:
    try:
        c, _ = srv.accept()
    except socket.timeout:
        break
    c.settimeout(10)
    try:
        if mode == "close":
            pass
        elif mode == "garbage":
            c.sendall(b"GET / HTTP/1.0\r\n\r\n")
        elif mode == "error":
            hdr = read_exact(c, 16)
            if hdr:
                magic, version, mtype, n, seq = struct.unpack("<IHHII", hdr)
                payload = read_exact(c, n) or b""
                tlen = struct.unpack_from("<H", payload, 1)[0]
                token = payload[3:3 + tlen]
                if token == b"good-token":
                    c.sendall(error_frame(12, "token good-token accepted; server busy", seq))
                else:
                    c.sendall(error_frame(6, "wrong token %r" % token, seq))
        time.sleep(0.05)
    except Exception as e:
        print("fake server:", e, file=sys.stderr)
    c.close()
EOF
  for mode in close error garbage; do
    rm -f "port_$mode"
    python3 fake_server.py "$mode" "port_$mode" > "fake_$mode.log" 2>&1 &
    fake_pid=$!
    for _ in $(seq 100); do [ -s "port_$mode" ] && break; sleep 0.05; done
    addr="127.0.0.1:$(cat "port_$mode")"
    for client in hmd projector loadgen; do
      bin="$build/clients/hysar-$client"
      out_for "$client"
      case $mode in
        close)
          expect_usage "$client server closes at once" "$addr.*closed" "$bin" "${T[@]}" --connect "$addr" "${out_args[@]}"
          ;;
        error)
          expect_usage "$client server answers Error" "$addr.*unauthorized \(6\).*wrong token" "$bin" --token wrong --connect "$addr" "${out_args[@]}"
          expect_usage "$client CRLF token file" "$addr.*server busy \(12\).*good-token accepted" "$bin" --token-file token_crlf --connect "$addr" "${out_args[@]}"
          ;;
        garbage)
          expect_usage "$client server sends no frame" "$addr.*bad (header|magic)" "$bin" "${T[@]}" --connect "$addr" "${out_args[@]}"
          ;;
      esac
    done
    kill "$fake_pid" 2> /dev/null
    wait "$fake_pid" 2> /dev/null
  done
else
  # scripts/setup.sh installs python3: without it these cases would not run, which is a failure.
  echo "FAIL: no python3 for the fake server cases (closes at once, answers Error, CRLF token)"
  failures=$((failures + 1))
fi

finish
