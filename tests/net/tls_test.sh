#!/usr/bin/env bash
# TLS end to end (docs/OPERATIONS.md, "TLS"): a self-signed certificate made with the documented
# openssl line, `hysar serve --tls-cert/--tls-key`, and every client over it: hysar-hmd trusting
# the certificate as its CA, hysar-projector pinning its fingerprint, hysar-loadgen, and the
# admin tool. Then what must be refused, each with its own message: a certificate signed by
# someone else, a wrong pin, a name the certificate does not carry, a plain client on the TLS
# port, TLS on a Unix socket, a key others may read, a key that is not the certificate's. The
# admin HTTP endpoint is HTTPS with the same certificate: /metrics over it; plain HTTP answered
# 400 naming HTTPS; a broken handshake counted. The server's Unix socket stays plain and keeps
# serving throughout.
set -euo pipefail
bin="$1"
dir=$(mktemp -d)
server=""
cleanup() { [[ -n "$server" ]] && kill -KILL "$server" 2>/dev/null; rm -rf "$dir"; }
trap cleanup EXIT
# A log's sanitizer report from its first line (its last lines are only the legend), else its end.
show_log() {  # LOG
  local at
  at=$(grep -n -m1 -E 'ERROR: AddressSanitizer|WARNING: ThreadSanitizer|runtime error:' "$1" | cut -d: -f1 || true)
  if [[ -n "$at" ]]; then sed -n "${at},$((at + 60))p" "$1"; else tail -n 20 "$1"; fi
}
fail() { echo "FAIL: $*"; for f in "$dir"/*.log; do echo "--- $f"; show_log "$f"; done; exit 1; }
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
  --admin-listen 127.0.0.1:0 > "$dir/serve.log" 2>&1 &
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

# The admin endpoint: HTTPS with the server's certificate; plain HTTP is told so; a broken
# handshake is closed and counted, and the operator is answered afterwards.
admin_port=$(sed -n 's|^admin endpoint on https://127\.0\.0\.1:\([0-9]*\)/.*|\1|p' "$dir/serve.log")
[[ -n "$admin_port" ]] || fail "no https:// admin endpoint in the start-up lines"
python3 - "$admin_port" "$dir/localhost.pem" "$dir/token" > "$dir/admin-https.log" 2>&1 <<'PY' || fail "admin endpoint over HTTPS: $(cat "$dir/admin-https.log")"
import socket, ssl, sys, urllib.request
port, ca, token = int(sys.argv[1]), sys.argv[2], open(sys.argv[3]).read().strip()
ctx = ssl.create_default_context(cafile=ca)
def metrics():
    req = urllib.request.Request(f"https://localhost:{port}/metrics",
                                 headers={"Authorization": f"Bearer {token}"})
    with urllib.request.urlopen(req, context=ctx, timeout=20) as r:
        assert r.status == 200, r.status
        return r.read().decode()
def value(text, name):
    return float(next(l.split()[-1] for l in text.splitlines() if l.startswith(name + " ")))
first = metrics()
assert value(first, "hysar_admin_tls_handshakes_failed_total") == 0, first[:200]
# Plain HTTP on the HTTPS port: 400, in plain text, naming HTTPS.
s = socket.create_connection(("127.0.0.1", port), timeout=10)
s.sendall(b"GET /metrics HTTP/1.1\r\nHost: x\r\n\r\n")
answer = b""
while True:
    c = s.recv(4096)
    if not c:
        break
    answer += c
assert answer.startswith(b"HTTP/1.1 400 ") and b"speaks HTTPS" in answer, answer[:200]
# A handshake that is not TLS at all, and one that stops half way: closed, each counted.
before = value(metrics(), "hysar_admin_tls_handshakes_failed_total")
for junk in (b"\x16\x03\x01\x00\x05hello", b"\x16\x03\x01"):
    s = socket.create_connection(("127.0.0.1", port), timeout=10)
    s.sendall(junk)
    s.shutdown(socket.SHUT_WR)
    s.settimeout(10)
    try:
        while s.recv(4096):
            pass
    except (ConnectionResetError, socket.timeout):
        pass
    s.close()
counted = value(metrics(), "hysar_admin_tls_handshakes_failed_total") - before
assert counted == 2, f"{counted} of 2 broken handshakes counted"
# A whole request, then the client's end of stream without a close_notify (scripts and probes
# often close so): still answered, over the half-closed socket.
raw = socket.create_connection(("127.0.0.1", port), timeout=10)
incoming, outgoing = ssl.MemoryBIO(), ssl.MemoryBIO()
tls = ctx.wrap_bio(incoming, outgoing, server_hostname="localhost")
def pump():
    data = outgoing.read()
    if data:
        raw.sendall(data)
def fill():
    c = raw.recv(65536)
    if c:
        incoming.write(c)
    else:
        incoming.write_eof()
    return bool(c)
while True:
    try:
        tls.do_handshake()
        break
    except ssl.SSLWantReadError:
        pump()
        fill()
pump()
tls.write(f"GET /metrics HTTP/1.1\r\nHost: localhost\r\nAuthorization: Bearer {token}\r\n"
          "Connection: close\r\n\r\n".encode())
pump()
raw.shutdown(socket.SHUT_WR)  # a FIN, no close_notify
answer = b""
while True:
    try:
        chunk = tls.read(65536)
        if not chunk:
            break
        answer += chunk
    except ssl.SSLWantReadError:
        if not fill():
            break
    except (ssl.SSLEOFError, ssl.SSLZeroReturnError):
        break
raw.close()
assert answer.startswith(b"HTTP/1.1 200 "), answer[:200]
assert b"hysar_admin_bad_requests_total" in answer, answer[:200]
# A client that does not trust the certificate is refused by its own check.
try:
    urllib.request.urlopen(f"https://localhost:{port}/metrics", timeout=10,
                           context=ssl.create_default_context())
    raise SystemExit("an untrusting client was answered")
except urllib.error.URLError as e:
    assert "CERTIFICATE_VERIFY_FAILED" in str(e), e
after = metrics()
assert value(after, "hysar_admin_bad_requests_total") >= 1, after
assert value(after, "hysar_admin_tls_handshakes_failed_total") >= 2, after
print("admin over HTTPS: /metrics 200, plain HTTP 400, failed handshakes",
      value(after, "hysar_admin_tls_handshakes_failed_total"))
PY

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
echo "TLS: served hmd (CA), projector and loadgen (pin), admin; refused 6 wrong connections; $(tail -n 1 "$dir/admin-https.log")"
