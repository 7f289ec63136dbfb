#!/usr/bin/env python3
"""HAProxy's view of the render nodes, from its runtime API (`show stat`).

Usage: haproxy_stat.py SOCKET [BACKEND]
Prints one line per server: BACKEND SERVER STATUS WEIGHT SESSIONS (spaces in the status as
'_', e.g. DRAIN_(agent)); with BACKEND, only that backend's servers. Used by scripts/cluster.sh
and tests/net/cluster_gateway_test.sh.
"""
import socket
import sys

if len(sys.argv) not in (2, 3):
    sys.exit(__doc__.strip())
s = socket.socket(socket.AF_UNIX)
s.connect(sys.argv[1])
s.sendall(b"show stat\n")
data = b""
while chunk := s.recv(65536):
    data += chunk
for row in data.decode().splitlines():
    f = row.split(",")
    # pxname, svname, ..., scur (4), ..., status (17), weight (18); skip the header and the
    # FRONTEND/BACKEND summary rows.
    if row.startswith("#") or len(f) <= 18 or f[1] in ("FRONTEND", "BACKEND"):
        continue
    if len(sys.argv) == 3 and f[0] != sys.argv[2]:
        continue
    print(f[0], f[1], f[17].replace(" ", "_"), f[18], f[4])
