#!/usr/bin/env python3
"""Makes an operator, a system account, an account with JetStream and a user in it for
nats-server's operator mode (what `nsc` makes; Debian has no nsc): Ed25519 nkeys and JWTs signed
with them. Writes DIR/operator.jwt, DIR/resolver.conf (for a nats-server configuration's
`include`: the operator, the system account, both accounts preloaded) and DIR/node.creds (the
user's JWT and nkey seed, mode 600), the file `hysar serve --cluster-creds` reads.
Usage: nats_creds.py DIR"""
import base64, hashlib, json, os, sys, time
from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey
from cryptography.hazmat.primitives import serialization

PREFIX = {"operator": 14 << 3, "account": 0, "user": 20 << 3}
SEED = 18 << 3


def crc16(data):
    crc = 0
    for b in data:
        crc ^= b << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1021) if crc & 0x8000 else crc << 1
            crc &= 0xFFFF
    return crc


def b32(data):
    return base64.b32encode(data).decode().rstrip("=")


def encode(prefix_bytes, raw):
    body = bytes(prefix_bytes) + raw
    return b32(body + crc16(body).to_bytes(2, "little"))


class Key:
    def __init__(self, kind):
        self.kind = kind
        self.sk = Ed25519PrivateKey.generate()
        raw_seed = self.sk.private_bytes(serialization.Encoding.Raw, serialization.PrivateFormat.Raw,
                                         serialization.NoEncryption())
        raw_pub = self.sk.public_key().public_bytes(serialization.Encoding.Raw,
                                                    serialization.PublicFormat.Raw)
        p = PREFIX[kind]
        self.public = encode([p], raw_pub)
        self.seed = encode([SEED | (p >> 5), (p & 31) << 3], raw_seed)


def b64url(data):
    return base64.urlsafe_b64encode(data).decode().rstrip("=")


def jwt(issuer, subject, name, nats):
    claims = {"iat": int(time.time()), "iss": issuer.public, "name": name, "sub": subject.public,
              "nats": nats}
    claims["jti"] = b32(hashlib.sha256(json.dumps(claims, sort_keys=True).encode()).digest())
    head = b64url(json.dumps({"typ": "JWT", "alg": "ed25519-nkey"}).encode())
    body = b64url(json.dumps(claims).encode())
    sig = issuer.sk.sign(f"{head}.{body}".encode())
    return f"{head}.{body}.{b64url(sig)}"


def main(out):
    out = os.path.abspath(out)
    op, sys_acct, acct, user = Key("operator"), Key("account"), Key("account"), Key("user")
    unlimited = {"subs": -1, "data": -1, "payload": -1, "imports": -1, "exports": -1,
                 "wildcards": True, "conn": -1, "leaf": -1,
                 "mem_storage": -1, "disk_storage": -1, "streams": -1, "consumer": -1}
    op_jwt = jwt(op, op, "hysar-op", {"type": "operator", "version": 2,
                                      "system_account": sys_acct.public})
    sys_jwt = jwt(op, sys_acct, "SYS", {"type": "account", "version": 2})
    acct_jwt = jwt(op, acct, "hysar", {"type": "account", "version": 2, "limits": unlimited})
    user_jwt = jwt(acct, user, "node", {"type": "user", "version": 2, "subs": -1, "data": -1,
                                        "payload": -1, "issuer_account": acct.public})
    with open(os.path.join(out, "operator.jwt"), "w") as f:
        f.write(op_jwt)
    with open(os.path.join(out, "resolver.conf"), "w") as f:
        f.write(f'operator: "{os.path.join(out, "operator.jwt")}"\nresolver: MEMORY\n'
                f'system_account: {sys_acct.public}\n'
                f'resolver_preload: {{ {acct.public}: "{acct_jwt}", {sys_acct.public}: "{sys_jwt}" }}\n')
    fd = os.open(os.path.join(out, "node.creds"), os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "w") as f:
        f.write(f"-----BEGIN NATS USER JWT-----\n{user_jwt}\n------END NATS USER JWT------\n\n"
                f"-----BEGIN USER NKEY SEED-----\n{user.seed}\n------END USER NKEY SEED------\n")


if __name__ == "__main__":
    main(sys.argv[1])
