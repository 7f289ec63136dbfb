#!/usr/bin/env bash
# TLS end to end (docs/OPERATIONS.md, "TLS"): a self-signed certificate made with the documented
# openssl line, `hysar serve --tls-cert/--tls-key`, and every client over it: hysar-hmd trusting
# the certificate as its CA, hysar-projector pinning its fingerprint, hysar-loadgen, and the
# admin tool. Then what must be refused, each with its own message: a certificate signed by
# someone else, a wrong pin, a name the certificate does not carry, a plain client on the TLS
# port, TLS on a Unix socket, a key others may read, a key that is not the certificate's. The
# server's Unix socket stays plain and keeps serving throughout.
set -euo pipefail
bin="$1"
dir=$(mktemp -d)
server=""
cleanup() { [[ -n "$server" ]] && kill -KILL "$server" 2>/dev/null; rm -rf "$dir"; }
trap cleanup EXIT
fail() { echo "FAIL: $*"; for f in "$dir"/*.log; do echo "--- $f"; tail -n 20 "$f"; done; exit 1; }
(umask 077 && echo "tls-test-token" > "$dir/token" && echo "tls-test-admin" > "$dir/admin")

# The README's one-line self-signed set-up; this certificate names localhost only (no IP).
selfsigned() {  # NAME SAN
  openssl req -x509 -newkey ec -pkeyopt ec_paramgen_curve:prime256v1 -nodes -days 30 \
    -subj "/CN=$1" -addext "subjectAltName=$2" -keyout "$dir/$1.key" -out "$dir/$1.pem" 2>/dev/null
  chmod 600 "$dir/$1.key"
}
selfsigned localhost DNS:localhost
selfsigned elsewhere DNS:elsewhere.example
pin=$(openssl x509 -noout -fingerprint -sha256 -in "$dir/localhost.pem")
other_pin=$(openssl x509 -noout -fingerprint -sha256 -in "$dir/elsewhere.pem")

# Refused before serving: a key others may read; a key that is not the certificate's.
cp "$dir/localhost.key" "$dir/open.key" && chmod 644 "$dir/open.key"
out=$("$bin/hysar" serve --listen 127.0.0.1:0 --token-file "$dir/token" \
  --tls-cert "$dir/localhost.pem" --tls-key "$dir/open.key" 2>&1) && fail "a world-readable key was taken"
grep -q -- "--tls-key $dir/open.key: others may read" <<< "$out" || fail "key mode: '$out'"
out=$("$bin/hysar" serve --listen 127.0.0.1:0 --token-file "$dir/token" \
  --tls-cert "$dir/localhost.pem" --tls-key "$dir/elsewhere.key" 2>&1) && fail "a mismatched key was taken"
grep -q "is not the key of --tls-cert" <<< "$out" || fail "key mismatch: '$out'"
out=$("$bin/hysar" serve --listen 127.0.0.1:0 --token-file "$dir/token" \
  --tls-cert "$dir/localhost.pem" 2>&1) && fail "a certificate without its key was taken"
grep -q "needs both --tls-cert and --tls-key" <<< "$out" || fail "cert alone: '$out'"

"$bin/hysar" serve --listen 127.0.0.1:0 --unix "$dir/s.sock" --token-file "$dir/token" \
  --admin-token-file "$dir/admin" --tls-cert "$dir/localhost.pem" --tls-key "$dir/localhost.key" \
  > "$dir/serve.log" 2>&1 &
server=$!
for _ in $(seq 300); do [[ -S "$dir/s.sock" ]] && grep -q "^TLS on" "$dir/serve.log" && break; sleep 0.1; done
port=$(sed -n 's/^serving .* on 127\.0\.0\.1:\([0-9]*\).*/\1/p' "$dir/serve.log")
[[ -n "$port" ]] || fail "no port in the start-up line"
# The start-up line prints the fingerprint clients pin: the one openssl computes.
grep -q "^TLS on 127.0.0.1:$port: SHA-256 fingerprint ${pin#*=}," "$dir/serve.log" \
  || fail "the start-up line does not print the certificate's fingerprint ${pin#*=}"
tok=(--token-file "$dir/token")

# Served over TLS: a headset trusting the certificate by name, a projector pinning it by IP.
"$bin/clients/hysar-hmd" --connect "localhost:$port" --tls-ca "$dir/localhost.pem" "${tok[@]}" \
  --angles 0 --scale 0.25 --name tls-hmd --out "$dir/h" > "$dir/hmd.log" 2>&1 || fail "hysar-hmd over TLS"
ls "$dir"/h/tls-hmd_*left*.png > /dev/null || fail "no layer written by the headset over TLS"
"$bin/clients/hysar-projector" --connect "127.0.0.1:$port" --tls-fingerprint "$pin" "${tok[@]}" \
  --frames 1 --out "$dir/p" > "$dir/projector.log" 2>&1 || fail "hysar-projector with a pinned certificate"
ls "$dir"/p/projector_v*.png > /dev/null || fail "no projector frame over TLS"
"$bin/clients/hysar-loadgen" --connect "127.0.0.1:$port" --tls-fingerprint "${pin#*=}" "${tok[@]}" \
  --viewers 2 --rate 10 --seconds 2 --scale 0.25 --json "$dir/loadgen.json" > "$dir/loadgen.log" 2>&1 \
  || fail "hysar-loadgen over TLS"
python3 - "$dir/loadgen.json" <<'PY' || fail "loadgen over TLS received no layers"
import json, sys
j = json.load(open(sys.argv[1]))
assert all(v["layers"] > 0 for v in j["per_viewer"]) and len(j["per_viewer"]) == 2, j
PY
"$bin/hysar" admin --connect "localhost:$port" --tls-ca "$dir/localhost.pem" \
  --token-file "$dir/admin" viewers > "$dir/admin.log" 2>&1 || fail "hysar admin over TLS"

# Refused, each with the reason, exit status 2, nothing written.
refused() {  # EXPECTED-TEXT ARGS...
  local want="$1"; shift
  local out
  if out=$("$bin/clients/hysar-hmd" "$@" "${tok[@]}" --angles 0 --scale 0.25 --retries 0 \
      --out "$dir/refused" 2>&1); then fail "taken: $*"; fi
  grep -q -- "$want" <<< "$out" || fail "for '$*' expected '$want', got: $out"
  [[ ! -e "$dir/refused" ]] || [[ -z "$(ls -A "$dir/refused")" ]] || fail "layers written despite: $*"
}
refused "certificate is not trusted" --connect "localhost:$port" --tls-ca "$dir/elsewhere.pem"
refused "not the pinned" --connect "127.0.0.1:$port" --tls-fingerprint "$other_pin"
refused "certificate is not trusted: ip address mismatch\|certificate is not trusted: IP address mismatch" \
  --connect "127.0.0.1:$port" --tls-ca "$dir/localhost.pem"
refused "speaks TLS on this port" --connect "127.0.0.1:$port"
refused "Unix socket" --connect "unix:$dir/s.sock" --tls
refused "is not a SHA-256 fingerprint" --connect "127.0.0.1:$port" --tls-fingerprint "sha256:xyz"
grep -q "TLS handshake failed" "$dir/serve.log" || fail "the server did not log the refused handshakes"

# The Unix socket stays plain, and the server kept serving through all of the above.
"$bin/clients/hysar-hmd" --connect "unix:$dir/s.sock" "${tok[@]}" --angles 10 --scale 0.25 \
  --name plain --out "$dir/u" > "$dir/unix.log" 2>&1 || fail "plain headset on the Unix socket"
ls "$dir"/u/plain_*left*.png > /dev/null || fail "no layer on the Unix socket"
kill -TERM "$server"
wait "$server" || fail "hysar serve exit $?"
server=""
echo "TLS: served hmd (CA), projector and loadgen (pin), admin; refused 6 wrong connections"
