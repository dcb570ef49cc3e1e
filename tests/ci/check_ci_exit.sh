#!/usr/bin/env bash
# CI's exit trap must keep CI's own exit status. It once ended a fully green CI with status 1:
# under `set -e` its kill of a build that had already finished failed, and the failure became
# CI's. This runs .ci/run's trap function, as .ci/run defines it, in a `set -euo pipefail` shell
# whose builds are long gone, after a passing script and after a failing one.
set -u
run_file="$1/.ci/run"
trap_fn="$(sed -n '/^stop_builds() {$/,/^}$/p' "$run_file")"
if [ -z "$trap_fn" ]; then
  echo "no stop_builds() { ... } in $run_file: the check below would test nothing" >&2
  exit 1
fi
gone_pid=$((4194304 + 17))  # above any pid_max: no such process group
run_case() {
  bash -c "set -euo pipefail; asan_build=$gone_pid; fuzz_build=$gone_pid
$trap_fn
trap stop_builds EXIT
$1"
}
run_case 'echo passing phases >/dev/null'; ok_status=$?
run_case 'false'; failed_status=$?
if [ "$ok_status" -ne 0 ]; then
  echo "a passing CI exits $ok_status after its trap (expected 0)" >&2; exit 1
fi
if [ "$failed_status" -eq 0 ]; then
  echo "a failing CI exits 0 after its trap (expected its failure)" >&2; exit 1
fi
echo "trap keeps the status: passing -> 0, failing -> $failed_status"
