#!/usr/bin/env bash
# The shipped systemd unit (config/manikind.service) keeps its sandbox: the overall exposure
# reported by `systemd-analyze security --offline=yes` must be 2.0 or lower (docs/daemon.md,
# "Running under systemd"). Offline mode reads the unit file only; no running systemd needed.
# Exit 77 = skipped (CTest SKIP_RETURN_CODE) only when systemd-analyze is missing or older than
# systemd 250 (no --offline).
set -euo pipefail
unit="${1:?usage: systemd_unit_score.sh <path to manikind.service>}"
max=2.0
[ -f "$unit" ] || { echo "FAIL: no unit file $unit"; exit 1; }
command -v systemd-analyze >/dev/null || { echo "SKIP: systemd-analyze is not installed"; exit 77; }
version=$(systemd-analyze --version | awk 'NR == 1 && $1 == "systemd" { print $2 + 0 }')
[ -n "$version" ] && [ "$version" -ge 250 ] \
  || { echo "SKIP: systemd-analyze is systemd ${version:-?}, --offline needs systemd 250 or later"; exit 77; }

out=$(systemd-analyze security --offline=yes --no-pager "$unit" 2>&1) \
  || { printf '%s\n' "$out"; echo "FAIL: systemd-analyze security failed on $unit"; exit 1; }
# "→ Overall exposure level for manikind.service: 1.6 OK 🙂" ("->" and ":-)" outside UTF-8 locales)
score=$(printf '%s\n' "$out" | sed -n 's/.*Overall exposure level for [^:]*: \([0-9][0-9]*\.[0-9]\).*/\1/p' | tail -n 1)
[ -n "$score" ] || { printf '%s\n' "$out"; echo "FAIL: no overall exposure level in the output above"; exit 1; }
printf '%s\n' "$out" | grep "Overall exposure level"
echo "exposure $score (allowed: $max or lower)"
if awk -v s="$score" -v m="$max" 'BEGIN { exit !(s > m) }'; then
  echo "FAIL: exposure $score is above $max; the settings systemd-analyze counts against the unit:"
  # ✗ in UTF-8 locales, "-" otherwise
  printf '%s\n' "$out" | grep -E '^(✗|-) ' || true
  exit 1
fi
