#!/usr/bin/env bash
# Holds the module boundaries of docs/ARCHITECTURE.md: no Vulkan call outside server/gpu/,
# no tinygltf outside server/scene/, no socket outside server/stream/ and clients/, no OpenCV
# outside server/calib/, no libusb outside clients/usb/usb_enumerate.cpp, no HTTP library outside
# server/admin/ (and its tests), no CLI11 outside options/options.cpp, no argument parsed by
# hand outside options/, no OpenSSL outside the two tls.cpp files (and the scene bus's HMAC),
# no NATS client outside server/cluster/scene_bus.cpp, no wire type behind the door (core, plot, scene, shading,
# optics, calib, gpu, render, loop: no protocol header included, no wire library linked), and
# hs_admin's links as docs/ARCHITECTURE.md draws them: it reads the server through its
# snapshot (hs_stream) and decodes layers (hs_codec, hs_protocol), never the GPU or the
# renderer; only the hysar commands' library (server/cli/) links it.
set -euo pipefail
cd "$(dirname "$0")/.."
fail=0
vk=$(grep -rnE '\bvk[A-Z][A-Za-z0-9]*\(' server --include='*.cpp' --include='*.hpp' | grep -v '^server/gpu/' || true)
if [[ -n "$vk" ]]; then echo "layers: Vulkan calls outside server/gpu/:"; echo "$vk"; fail=1; fi
gl=$(grep -rn 'tiny_gltf' server clients tests --include='*.cpp' --include='*.hpp' 2>/dev/null | grep -v '^server/scene/' || true)
if [[ -n "$gl" ]]; then echo "layers: tinygltf outside server/scene/:"; echo "$gl"; fail=1; fi
so=$(grep -rnE '#include <(sys/socket|netinet/in|asio)' server --include='*.cpp' --include='*.hpp' | grep -v '^server/stream/' || true)
if [[ -n "$so" ]]; then echo "layers: sockets outside server/stream/:"; echo "$so"; fail=1; fi
cv=$(grep -rn '#include <opencv2' server clients --include='*.cpp' --include='*.hpp' | grep -v '^server/calib/' || true)
if [[ -n "$cv" ]]; then echo "layers: OpenCV outside server/calib/:"; echo "$cv"; fail=1; fi
usb=$(grep -rnE '#include <libusb|\blibusb_[a-z_]+\(' server clients tests --include='*.cpp' --include='*.hpp' 2>/dev/null | grep -v '^clients/usb/usb_enumerate\.cpp:' || true)
if [[ -n "$usb" ]]; then echo "layers: libusb outside clients/usb/usb_enumerate.cpp:"; echo "$usb"; fail=1; fi
http=$(grep -rn '#include <httplib' server clients tests --include='*.cpp' --include='*.hpp' 2>/dev/null | grep -vE '^(server|tests)/admin/' || true)
if [[ -n "$http" ]]; then echo "layers: cpp-httplib outside server/admin/:"; echo "$http"; fail=1; fi
cli11=$(grep -rn '#include <CLI/' server clients tests options --include='*.cpp' --include='*.hpp' 2>/dev/null | grep -v '^options/options\.cpp:' || true)
if [[ -n "$cli11" ]]; then echo "layers: CLI11 outside options/options.cpp (programs read options through options/options.hpp):"; echo "$cli11"; fail=1; fi
# Arguments are read by options/ alone (options/options.hpp, options/numbers.hpp). Outside it, in
# any program or test: an element of argv compared with a string (strcmp(argv[i], ...),
# std::string_view(argv[i]) == ..., argv[i] == ...), or a value taken by hand (args[++i]).
# In the command layer and the clients, which hold no other reason to: an option's name
# compared with a string ("a == \"--help\""), the shape of a hand-written option loop.
argv_rx='(str(n)?cmp|strcasecmp)[[:space:]]*\([[:space:]]*argv|(std::)?string(_view)?[[:space:]]*[({][[:space:]]*argv[[:space:]]*\[|argv[[:space:]]*\[[^]]*\][[:space:]]*[!=]=|[!=]=[[:space:]]*argv[[:space:]]*\[|\bargs?[[:space:]]*\[[[:space:]]*\+\+'
handargv=$(grep -rnE "$argv_rx" server clients tests examples --include='*.cpp' --include='*.hpp' --include='*.c' --include='*.h' 2>/dev/null || true)
opt_rx='[!=]=[[:space:]]*"--?[A-Za-z]|"--?[A-Za-z][^"]*"[[:space:]]*[!=]='
handopt=$(grep -rnE "$opt_rx" server/cli server/main.cpp clients --include='*.cpp' --include='*.hpp' 2>/dev/null || true)
if [[ -n "$handargv$handopt" ]]; then
  echo "layers: arguments read by hand outside options/ (read them with options/options.hpp):"
  if [[ -n "$handargv" ]]; then echo "$handargv"; fi
  if [[ -n "$handopt" ]]; then echo "$handopt"; fi
  fail=1
fi
tls=$(grep -rn '#include <openssl/' server clients --include='*.cpp' --include='*.hpp' 2>/dev/null | grep -vE '^(server/stream/tls\.cpp|clients/net/tls\.cpp|server/cluster/scene_bus\.cpp):' || true)
if [[ -n "$tls" ]]; then echo "layers: OpenSSL outside server/stream/tls.cpp, clients/net/tls.cpp and server/cluster/scene_bus.cpp (the bus's HMAC):"; echo "$tls"; fail=1; fi
nats=$(grep -rnE '#include <nats' server clients tests cli --include='*.cpp' --include='*.hpp' 2>/dev/null | grep -v '^server/cluster/scene_bus\.cpp:' || true)
if [[ -n "$nats" ]]; then echo "layers: nats.h outside server/cluster/scene_bus.cpp:"; echo "$nats"; fail=1; fi
# Behind the door: the session (server/stream/session.cpp) converts every wire message into
# domain types and the encoder writes the wire on the way out, so no wing behind them includes a
# protocol header (or the codec's wire half, or the network server), nor links the libraries
# that would bring them.
wings=(server/core server/plot server/scene server/shading server/optics server/calib server/gpu
       server/render server/loop)
door=$(grep -rnE '#include "(protocol/|codec/layer_codec\.hpp|stream/|clients/)' "${wings[@]}" --include='*.cpp' --include='*.hpp' || true)
if [[ -n "$door" ]]; then echo "layers: behind the door, a file sees the wire (the session converts; loop/viewer.hpp holds the domain types):"; echo "$door"; fail=1; fi
for w in "${wings[@]}"; do
  links=$(tr '\n' ' ' < "$w/CMakeLists.txt" | grep -oE 'target_link_libraries\([^)]*\)' | grep -oE '\bhs_(protocol|stream|client[a-z_]*|admin)\b' || true)
  if [[ -n "$links" ]]; then echo "layers: $w links the wire's side: $(echo $links)"; fail=1; fi
done
adm=$(grep -rnE '#include "(gpu|render|shading|optics|calib|installation|bench)/|#include "stream/|#include <asio' server/admin --include='*.cpp' --include='*.hpp' | grep -vE '#include "stream/(snapshot|token|tls)\.hpp"' || true)
if [[ -n "$adm" ]]; then echo "layers: server/admin/ reaches past the server's snapshot:"; echo "$adm"; fail=1; fi
adm_links=$(tr '\n' ' ' < server/admin/CMakeLists.txt | grep -oE 'target_link_libraries\(hs_admin[^)]*\)' || true)
for lib in $(echo "$adm_links" | grep -oE '\bhs_[a-z_]+' | grep -v '^hs_admin$'); do
  case "$lib" in hs_stream|hs_codec|hs_protocol|hs_core) ;;
    *) echo "layers: hs_admin links $lib (allowed: hs_stream, hs_codec, hs_protocol, hs_core)"; fail=1 ;;
  esac
done
users=$(grep -rln 'hs_admin\b' --include=CMakeLists.txt . 2>/dev/null | grep -vE '^\./(build[^/]*|server/admin|tests)/|^\./(server/cli/)?CMakeLists\.txt$' || true)
if [[ -n "$users" ]]; then echo "layers: hs_admin linked outside the hysar commands (server/cli/) and its tests:"; echo "$users"; fail=1; fi
if [[ $fail -ne 0 ]]; then exit 1; fi
echo "layers: module boundaries hold"
