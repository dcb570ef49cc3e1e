#!/usr/bin/env bash
# Builds the Debian package of the two programs: build/manikind_<version>_<arch>.deb (the
# service, its configuration and data layout: docs/daemon.md, "The Debian package").
#   scripts/package.sh                 the project's version (CMakeLists.txt)
#   scripts/package.sh 0.1.1           another version, e.g. an upgrade to test (no reconfigure)
# Needs the default build configured (scripts/setup.sh) and dpkg-dev (dpkg-shlibdeps finds the
# libraries the package depends on). Prints the path of the .deb on its last line.
set -euo pipefail
cd "$(dirname "$0")/.."
build=${MANIKIND_BUILD_DIR:-build}
version=${1:-}
[ -f "$build/CPackConfig.cmake" ] || { echo "package: no $build/CPackConfig.cmake; run scripts/setup.sh first" >&2; exit 2; }
command -v dpkg-shlibdeps >/dev/null || { echo "package: dpkg-shlibdeps is missing (apt-get install dpkg-dev)" >&2; exit 2; }
cmake --build "$build" -j 2 --target manikin manikind manikind_modules >/dev/null
# cpack writes the .deb and _CPack_Packages/ into the build folder (CPACK_PACKAGE_DIRECTORY).
out=$(cd "$build" && MANIKIND_PACKAGE_VERSION="$version" cpack -G DEB 2>&1) || { printf '%s\n' "$out" >&2; exit 1; }
deb=$(printf '%s\n' "$out" | sed -n 's/^CPack: - package: \(.*\.deb\) generated\.$/\1/p' | tail -n 1)
[ -n "$deb" ] && [ -f "$deb" ] || { printf '%s\n' "$out" >&2; echo "package: cpack named no .deb" >&2; exit 1; }
echo "$deb"
