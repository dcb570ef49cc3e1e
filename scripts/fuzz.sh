#!/usr/bin/env bash
# Builds the fuzz targets (the asan preset's clang build: libFuzzer, ASan + UBSan, in build-asan/)
# and runs every one for a bounded time from its seed corpus in fuzz/corpus/<target>/.
#   scripts/fuzz.sh [seconds_per_target]      default 30
# New corpus entries and any crash-* / leak-* / timeout-* reproducer go to a temporary folder,
# never into the repository; on a finding it is kept and named. Exit status 1 on any finding.
set -euo pipefail
cd "$(dirname "$0")/.."
seconds="${1:-30}"
case "$seconds" in ''|*[!0-9]*) echo "fuzz: seconds_per_target must be a whole number, not '$seconds'" >&2; exit 2 ;; esac

# The fuzz build preset is the asan configuration's `fuzzers` target: after `scripts/setup.sh
# --tests asan` (which builds them with the tests) this only checks they are current.
cmake --preset asan >/dev/null
# Two cores, as scripts/setup.sh builds; MANIKIND_FUZZ_JOBS=1 on a shared machine.
cmake --build --preset fuzz -j "${MANIKIND_FUZZ_JOBS:-2}"

work="$(mktemp -d "${TMPDIR:-/tmp}/manikind-fuzz.XXXXXX")"
# One target: its verdict line on stdout, a finding also on stderr; exit 1 on a finding.
run_target() {
  local corpus="$1" target binary
  target="$(basename "$corpus")"
  binary="build-asan/bin/$target"
  [ -x "$binary" ] || { echo "fuzz: $target: no binary $binary (a corpus without a target?)" >&2; return 1; }
  mkdir -p "$work/$target/new" "$work/$target/tmp"
  # The first directory receives what the fuzzer finds new; the seeds are only read.
  # TMPDIR: the targets that need files (recording, control API) make them there.
  if TMPDIR="$work/$target/tmp" "$binary" "$work/$target/new" "$corpus" \
       -max_total_time="$seconds" -rss_limit_mb=2048 -timeout=10 -print_final_stats=1 \
       -artifact_prefix="$work/$target/" >"$work/$target/log" 2>&1; then
    echo "fuzz: $target: $(grep -o 'stat::number_of_executed_units: *[0-9]*' "$work/$target/log" | grep -o '[0-9]*$') runs in ${seconds} s, no finding"
  else
    echo "fuzz: $target: FINDING (log and reproducer kept in $work/$target/)" >&2
    grep -E '^(==[0-9]+==ERROR|SUMMARY|.*check failed|.*runtime error|.*uncaught exception)' "$work/$target/log" | head -5 >&2 || true
    return 1
  fi
}
# The targets run two at a time (MANIKIND_FUZZ_JOBS; each fuzzes on one core): 12 targets at 5 s
# took 60 s one after another.
jobs_at_once="${MANIKIND_FUZZ_JOBS:-2}"
findings=0
running=0
for corpus in fuzz/corpus/*/; do
  if [ "$running" -ge "$jobs_at_once" ]; then
    wait -n || findings=1
    running=$((running - 1))
  fi
  run_target "$corpus" &
  running=$((running + 1))
done
while [ "$running" -gt 0 ]; do
  wait -n || findings=1
  running=$((running - 1))
done
if [ "$findings" -eq 0 ]; then rm -rf "$work"; else exit 1; fi
