#!/usr/bin/env bash
# Installs what is missing on a Debian 12 machine (as root), then configures and builds.
#   scripts/setup.sh                  release build in build/: the two programs, manikin and manikind
#   scripts/setup.sh --tests          the same, plus what the test suite drives (peers, tools), and
#                                     every target: tests and benchmarks
#   scripts/setup.sh [--tests] asan   AddressSanitizer + UBSan build in build-asan/ (clang), the
#                                     libFuzzer targets in the same build (scripts/fuzz.sh runs them)
# Safe to run again: it installs nothing that is already there and rebuilds incrementally.
set -euo pipefail
cd "$(dirname "$0")/.."
preset=default
with_tests=no
for arg in "$@"; do
  case "$arg" in
    --tests) with_tests=yes ;;
    default|asan) preset="$arg" ;;
    *) echo "setup: unknown argument '$arg' (expected --tests, default or asan)" >&2; exit 2 ;;
  esac
done

packages=(
  build-essential cmake ninja-build pkg-config git
  libmodbus-dev libboost-dev libsqlite3-dev sqlite3 libsystemd-dev
  libspdlog-dev libfmt-dev catch2 libtomlplusplus-dev nlohmann-json3-dev libcli11-dev libeigen3-dev
  # `manikin export --format hdf5`.
  libhdf5-dev
  # `manikin archive push`: the PostgreSQL client library (docs/archive.md).
  libpq-dev
  # SHA-256 of configurations and set-ups: OpenSSL's libcrypto.
  libssl-dev
  # Notifications by webhook and e-mail (docs/daemon.md, "Notifications").
  libcurl4-openssl-dev
)
if [ "$with_tests" = yes ]; then
  packages+=(
    # Peers not written here, for the interoperability tests (tests/interop/).
    mbpoll python3 python3-serial python3-pymodbus python3-serial-asyncio
    # systemd-analyze scores the shipped unit's sandbox (tests/daemon/systemd_unit_score.sh).
    systemd
    # A real browser for the operator console, and a Prometheus parser for /metrics (tests/web/).
    chromium chromium-driver python3-selenium python3-prometheus-client
    # The tools labs read exports with (tests/export/): h5py, pandas and GNU Octave; rsvg-convert
    # renders every SVG the tool writes so a malformed one fails (tests/plot/).
    python3-h5py python3-pandas octave librsvg2-bin
    # The README's plotting example (docs/examples/plot_trial.py), run by tests/export/.
    python3-matplotlib
    # A real SMTP server to receive the daemon's e-mail (tests/daemon/notify_peers.py).
    python3-aiosmtpd
    # A real PostgreSQL 15 server, started per test by tests/archive/ (initdb, pg_ctl).
    postgresql
    # The load generator of the daemon's soak under load (tests/soak/).
    stress-ng
    # A clean Debian 12 root to install, upgrade and purge the package in (tests/package/);
    # dpkg-dev (dpkg-shlibdeps, for scripts/package.sh) comes with build-essential.
    debootstrap
  )
fi
if [ "$with_tests" = yes ] || [ "$preset" = asan ]; then
  packages+=(
    # The asan preset and scripts/fuzz.sh: clang with libFuzzer and the sanitizer runtimes
    # (libclang-rt-14-dev is only recommended by clang, and recommends are not installed);
    # llvm-symbolizer for traces.
    clang libclang-rt-14-dev llvm
  )
fi
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
# Two cores: parallel 2 keeps memory modest and the machine responsive. Without --tests only the
# two programs are built (what the main job runs); --tests builds everything, tests and
# benchmarks included (issue 36: a newcomer's first command builds what it runs).
if [ "$with_tests" = yes ]; then
  cmake --build --preset "$preset" -j 2
else
  cmake --build --preset "$preset" -j 2 --target manikin manikind
fi
