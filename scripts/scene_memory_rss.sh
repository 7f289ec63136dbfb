#!/usr/bin/env bash
# Measures (does not test) what N scene updates do to a `hysar serve` process's resident set,
# beside the scene memory the server counts itself (docs/OPERATIONS.md, "Scene memory"): the
# paper's room served on the CPU device, two colourings of it pushed alternately with
# `hysar admin scene push`, RSS read from /proc after 30, 75 and N updates.
# usage: scripts/scene_memory_rss.sh [BUILD_DIR] [N] [PORT]
#   HYSAR_MALLOC_TRIM=0 and HYSAR_WARM_UP=0 in the environment pass through to the server.
set -uo pipefail
cd "$(dirname "$0")/.."
B=${1:-build}; N=${2:-150}; PORT=${3:-17731}
D=$(mktemp -d)
trap 'rm -rf "$D"' EXIT
echo viewer-token > "$D/token"; echo admin-token > "$D/admin"; chmod 600 "$D/token" "$D/admin"
python3 - configs/exp1-room.json "$D" <<'PY'
import json, sys
j = json.load(open(sys.argv[1]))
for name, albedo in (("a", [0.2, 0.6, 0.9]), ("b", [0.9, 0.5, 0.1])):
    j["material"]["albedo"] = albedo
    json.dump(j, open(f"{sys.argv[2]}/{name}.json", "w"))
PY
"$B/hysar" serve --scene configs/exp1-room.json --listen 127.0.0.1:$PORT --token-file "$D/token" \
  --admin-token-file "$D/admin" --device cpu > "$D/log" 2>&1 &
pid=$!
adm() { "$B/hysar" admin --connect 127.0.0.1:$PORT --token-file "$D/admin" "$@"; }
# Started once the first scene version is built (the server answers before that).
held() {
  adm stats --json 2> /dev/null |
    python3 -c 'import json, sys; print(json.load(sys.stdin)["scene_memory"]["versions_held"])'
}
for _ in $(seq 1 300); do [[ "$(held 2> /dev/null)" == 1 ]] && break; sleep 1; done
rss() { awk '/VmRSS/{print $2}' "/proc/$pid/status"; }
echo "started: RSS $(rss) KiB"
t0=$(date +%s)
for i in $(seq 1 "$N"); do
  f="$D/a.json"; ((i % 2)) && f="$D/b.json"
  adm scene push "$f" > /dev/null || echo "update $i: refused"
  if ((i == 30 || i == 75 || i == N)); then
    echo "after $i updates: RSS $(rss) KiB ($(($(date +%s) - t0)) s)"
  fi
done
sleep 5
echo "5 s later: RSS $(rss) KiB"
adm stats --json | python3 -c 'import json, sys; print(json.dumps(json.load(sys.stdin)["scene_memory"]))'
kill "$pid"; wait "$pid"
