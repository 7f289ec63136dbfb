#!/usr/bin/env bash
# Installs the missing Debian packages (apt-get, as root) and builds into build/. Idempotent.
# Usage: scripts/setup.sh [extra cmake args]
set -euo pipefail
cd "$(dirname "$0")/.."

PACKAGES=(
  build-essential cmake ninja-build pkg-config clang libclang-rt-14-dev python3 util-linux
  libvulkan-dev mesa-vulkan-drivers vulkan-validationlayers glslang-tools
  libglm-dev libfmt-dev nlohmann-json3-dev libtinygltf-dev libstb-dev libopenexr-dev
  clang-format libgtest-dev libbenchmark-dev libasio-dev liblz4-dev libzstd-dev libjpeg-dev libglfw3-dev libgl-dev xvfb xauth
  libusb-1.0-0-dev usb.ids umockdev haproxy nats-server libnats-dev gdb
  libopencv-dev libopencv-contrib-dev
  libspdlog-dev libcpp-httplib-dev libssl-dev openssl libcli11-dev chromium chromium-driver python3-selenium
  python3-cryptography
)

missing=()
for p in "${PACKAGES[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if ((${#missing[@]})); then
  echo "setup: installing ${missing[*]}"
  if [[ $(id -u) -ne 0 ]]; then
    echo "setup: missing packages and not root; run as root or install: ${missing[*]}" >&2
    exit 1
  fi
  export DEBIAN_FRONTEND=noninteractive
  apt-get update -qq
  apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi

jobs=$(nproc 2>/dev/null || echo 2)
# A unity build: each target's sources compiled a few at a time, so the headers they share are
# parsed and their templates compiled once per batch (about half the time of one file at a time;
# pass -DCMAKE_UNITY_BUILD=OFF for quicker rebuilds of a single changed file).
cmake -S . -B build -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DCMAKE_UNITY_BUILD=ON "$@" >/dev/null
cmake --build build -j "$jobs"
