#!/usr/bin/env bash
# Holds the module boundaries of docs/ARCHITECTURE.md: no Vulkan call outside server/gpu/,
# no tinygltf outside server/scene/, no socket outside server/stream/ and clients/, no OpenCV
# outside server/calib/, no libusb outside clients/usb_enumerate.cpp.
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
usb=$(grep -rnE '#include <libusb|\blibusb_[a-z_]+\(' server clients tests --include='*.cpp' --include='*.hpp' 2>/dev/null | grep -v '^clients/usb_enumerate\.cpp:' || true)
if [[ -n "$usb" ]]; then echo "layers: libusb outside clients/usb_enumerate.cpp:"; echo "$usb"; fail=1; fi
if [[ $fail -ne 0 ]]; then exit 1; fi
echo "layers: module boundaries hold"
