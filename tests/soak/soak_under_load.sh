#!/usr/bin/env bash
# Issue 30, item 5: the daemon under load. A campaign on the simulated lab at --speed 10 while
# stress-ng keeps every core and the disk busy; the daemon is stopped (SIGTERM) and started again
# RUNS times, each run continuing the same campaign. Every run must exit 0 with nothing lost
# (its own count: every reading accepted stored, none skipped as a duplicate, dropped or lost, no
# write left waiting), and at the end the database must pass SQLite's integrity check and hold
# exactly the readings the runs said they stored. Exit 77 (skipped) where stress-ng is missing.
#   soak_under_load.sh <manikind binary> [runs] [seconds per run]
set -euo pipefail
manikind="$1"
runs="${2:-10}"
seconds="${3:-15}"
command -v stress-ng >/dev/null || { echo "stress-ng is not installed: skipped"; exit 77; }

dir="$(mktemp -d /tmp/manikind-soak.XXXXXX)"
stress_pid=""
cleanup() {
  [[ -n "$stress_pid" ]] && kill "$stress_pid" 2>/dev/null && wait "$stress_pid" 2>/dev/null
  rm -rf "$dir"
}
trap cleanup EXIT

cat >"$dir/plan.toml" <<'PLAN'
name = "soak"
replicates = 2
trial_duration_min = 35
[[cases]]
id = 1
chamber_temp_c = 35.0
chamber_rh_pct = 27.0
skin_setpoint_c = 35.0
wet = true
sweat_rate_g_m2_h = 300
PLAN
cat >"$dir/lab.toml" <<CONF
[lab]
database = "$dir/soak.db"
[api]
socket = "$dir/manikind.sock"
[simulation]
runtime_dir = "$dir/sim"
[recorder]
crash_ring_dir = "$dir"
CONF

# Every core busy with CPU work, and the disk with writes and syncs in this folder's file system.
stress-ng --cpu "$(nproc)" --hdd 1 --hdd-bytes 64M --temp-path "$dir" --timeout $(( runs * (seconds + 10) + 60 ))s \
  --quiet &
stress_pid=$!

stored_total=0
for run in $(seq 1 "$runs"); do
  "$manikind" --config "$dir/lab.toml" --speed 10 --campaign "$dir/plan.toml" >"$dir/out.$run" 2>"$dir/err.$run" &
  pid=$!
  # The daemon's own word that it is up (its start line), then the run's length under load.
  for _ in $(seq 1 600); do grep -q "^manikind: " "$dir/out.$run" 2>/dev/null && break; kill -0 "$pid" 2>/dev/null || break; sleep 0.1; done
  sleep "$seconds"
  kill -TERM "$pid" 2>/dev/null || true
  rc=0; wait "$pid" || rc=$?
  summary="$(grep '^manikind: stopped:' "$dir/out.$run" || true)"
  echo "run $run: exit $rc; ${summary:-no summary}"
  if [[ $rc -ne 0 || -z "$summary" ]] || grep -Eq "terminate|internal error|Sanitizer" "$dir/err.$run"; then
    echo "run $run failed; its stderr:"; tail -n 30 "$dir/err.$run"; exit 1
  fi
  # "manikind: stopped: A readings accepted, S stored, D re-sent duplicates, X dropped, L lost; W writes waiting"
  read -r accepted stored duplicates dropped lost waiting < <(echo "$summary" | grep -Eo '[0-9]+' | head -n 6 | xargs)
  if (( accepted != stored || duplicates != 0 || dropped != 0 || lost != 0 || waiting != 0 || accepted == 0 )); then
    echo "run $run lost readings or writes: $summary"; exit 1
  fi
  stored_total=$(( stored_total + stored ))
done

python3 - "$dir/soak.db" "$stored_total" <<'PY'
import sqlite3, sys
db = sqlite3.connect(f"file:{sys.argv[1]}?mode=ro", uri=True)
check = db.execute("PRAGMA integrity_check").fetchall()
rows = db.execute("SELECT (SELECT count(*) FROM samples) + (SELECT count(*) FROM idle_samples)").fetchone()[0]
trials = db.execute("SELECT count(*) FROM trials").fetchone()[0]
print(f"integrity_check: {check[0][0]}; {rows} readings stored in the database, {sys.argv[2]} by the runs' count; {trials} trials")
sys.exit(0 if check == [("ok",)] and rows == int(sys.argv[2]) else 1)
PY
