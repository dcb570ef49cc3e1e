#!/usr/bin/env bash
# Installs what is missing on a Debian 12 machine (as root), then configures and builds.
#   scripts/setup.sh            release build in build/
#   scripts/setup.sh asan       AddressSanitizer + UBSan build in build-asan/
# Safe to run again: it installs nothing that is already there and rebuilds incrementally.
set -euo pipefail
cd "$(dirname "$0")/.."
preset="${1:-default}"

packages=(
  build-essential cmake ninja-build pkg-config git
  libmodbus-dev libboost-dev libsqlite3-dev sqlite3
  libspdlog-dev libfmt-dev catch2 libtomlplusplus-dev nlohmann-json3-dev libcli11-dev libeigen3-dev
  # Peers not written here, for the interoperability tests (tests/interop/).
  mbpoll python3 python3-serial python3-pymodbus python3-serial-asyncio
)
missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ "${#missing[@]}" -gt 0 ]; then
  echo "setup: installing ${missing[*]}"
  if [ "$(id -u)" -ne 0 ]; then sudo=sudo; else sudo=; fi
  $sudo apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi

cmake --preset "$preset" >/dev/null
# Two cores: parallel 2 keeps memory modest and the machine responsive.
cmake --build --preset "$preset" -j 2
