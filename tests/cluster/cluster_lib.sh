# Shared by the cluster tests (sourced): a temporary folder cleaned on exit, render nodes on
# loopback and the admin pushes that change their scene. Before sourcing, a script sets `bin`
# (the build folder); before start_node, `url` (the bus) and, if any, `node_flags` (an array of
# flags every node gets: credentials, replicas).
dir=$(mktemp -d)
pids=()     # render nodes and clients, killed on exit
servers=()  # nats-servers, killed on exit
node_flags=()
src="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
cleanup() {
  for p in "${pids[@]}" "${servers[@]}"; do kill -KILL "$p" 2>/dev/null || true; done
  wait 2>/dev/null || true
  rm -rf "$dir"
}
trap cleanup EXIT
# A log's last lines, or, where a sanitizer reported, its report from the first line on (the
# last lines of an ASan report are its legend, not the stack).
show_log() {  # LOG
  local at
  at=$(grep -n -m1 -E 'ERROR: AddressSanitizer|WARNING: ThreadSanitizer|runtime error:' "$1" | cut -d: -f1 || true)
  if [[ -n "$at" ]]; then sed -n "${at},$((at + 60))p" "$1"; else tail -n 12 "$1"; fi
}
# Where gdb is installed: the scene-bus threads of every render node still running, so that a
# node that stopped taking the bus's values shows where its watch is.
bus_stacks() {
  command -v gdb > /dev/null || return 0
  local v n p
  for v in ${!pid_*}; do
    n=${v#pid_}; p=${!v}
    kill -0 "$p" 2>/dev/null || continue
    echo "--- node $n: threads in the scene bus (gdb)"
    timeout 30 gdb -batch -p "$p" -ex "thread apply all bt 12" 2>/dev/null \
      | awk '/^Thread /{if (t ~ /SceneBus|kvWatcher|kvStore|js_/) printf "%s", t; t=""} {t=t $0 "\n"}
             END{if (t ~ /SceneBus|kvWatcher|kvStore|js_/) printf "%s", t}' | head -80
  done
}
fail() { echo "FAIL: $*"; for f in "$dir"/*.log; do echo "--- $f"; show_log "$f"; done; bus_stacks; exit 1; }
command -v nats-server > /dev/null || fail "nats-server is not installed (scripts/setup.sh)"
free_port() { python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])'; }
# Waits for a nats-server's log to say it is ready.
nats_ready() {  # LOG
  for _ in $(seq 100); do grep -q "Server is ready" "$1" && return 0; sleep 0.1; done
  fail "nats-server did not start ($1)"
}
# A render node on a free port (port_NAME, pid_NAME), started in the background.
launch_node() {  # NAME [more flags]
  local name=$1 port; shift; port=$(free_port)
  eval "port_$name=$port"
  LP_NUM_THREADS=1 "$bin/hysar" serve --listen "127.0.0.1:$port" --token-file "$dir/token" \
    --admin-token-file "$dir/admin" --cluster "$url" --node-id "$name" "${node_flags[@]}" "$@" \
    > "$dir/node-$name.log" 2>&1 &
  pids+=($!)
  eval "pid_$name=$!"
}
# Waits until a launched node prints "serving"; fails at once if it exits first.
wait_node() {  # NAME
  local name=$1 pid; pid=$(eval echo "\$pid_$1")
  for _ in $(seq 600); do
    grep -q "^serving" "$dir/node-$name.log" && return 0
    kill -0 "$pid" 2>/dev/null || fail "node $name exited before serving"
    sleep 0.1
  done
  fail "node $name did not start within 60 s"
}
start_node() { launch_node "$@"; wait_node "$1"; }  # NAME [more flags]
# The room file renamed "room NAME", pushed through a node as an admin.
push() {  # NODE NAME
  sed "s/\"name\": \"HySAR experiment 1 room[^\"]*\"/\"name\": \"room $2\"/" "$src/configs/exp1-room.json" > "$dir/room-$2.json"
  "$bin/hysar" admin --connect "127.0.0.1:$(eval echo \$port_$1)" --token-file "$dir/admin" \
    --timeout-ms 20000 scene push "$dir/room-$2.json"
}
# The versions a node started on and applied, in order (not those it refused).
applied() { grep -v "cannot be served" "$dir/node-$1.log" | grep -oE "scene version [0-9]+(:|$)" | grep -oE "[0-9]+" | tr '\n' ' '; }
last_applied() { applied "$1" | awk '{print $NF}'; }
same_everywhere() { local v=$1; shift; for n in "$@"; do [[ "$(last_applied "$n")" == "$v" ]] || return 1; done; }
# True once CONDITION holds, within SECONDS.
within() {  # SECONDS CONDITION
  local end=$(( $(date +%s%N) + $1 * 1000000000 ))
  while (( $(date +%s%N) < end )); do eval "$2" && return 0; sleep 0.1; done
  return 1
}
