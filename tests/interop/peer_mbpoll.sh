#!/usr/bin/env bash
# Peer test: Debian's mbpoll (a Modbus client not written here) reads the simulated chamber's
# process value and writes a temperature setpoint with the documented register map
# (README: mbpoll numbers registers from 1, so protocol address N is -r N+1); the simulated
# world follows it. Exit 77 = skipped (CTest SKIP_RETURN_CODE) only when mbpoll is missing.
set -euo pipefail
manikin="$1"
command -v mbpoll >/dev/null || { echo "SKIP: mbpoll is not installed (scripts/setup.sh installs it)"; exit 77; }
dir=$(mktemp -d)
pid=
cleanup() { [ -n "$pid" ] && kill "$pid" 2>/dev/null; wait 2>/dev/null; rm -rf "$dir"; }
trap cleanup EXIT
mkfifo "$dir/endpoints"
"$manikin" sim serve --speed 100 --json --runtime-dir "$dir/rt" > "$dir/endpoints" &
pid=$!
read -r endpoints < "$dir/endpoints"          # blocks until the lab is up
port=$(/usr/bin/python3 -c 'import json,sys; print(json.loads(sys.argv[1])["chamber"]["port"])' "$endpoints")

read_reg() {  # value of one holding register (1-based reference), unit 1
  mbpoll -m tcp -p "$port" -a 1 -t 4 -r "$1" -c 1 -1 127.0.0.1 | awk -F'\t' '/^\[/ { print $2 }'
}
pv=$(read_reg 2)                               # PV.IN, address 1, x10
echo "chamber PV read by mbpoll: $pv (x10 °C)"
[ "$pv" -ge 200 ] && [ "$pv" -le 240 ] || { echo "FAIL: PV $pv, expected the initial 22 °C (220)"; exit 1; }
mbpoll -m tcp -p "$port" -a 1 -t 4 -r 27 -1 127.0.0.1 350 >/dev/null   # Rm.SP, address 26: 35.0 °C
wsp=$(read_reg 6)                              # WKG.SP, address 5
[ "$wsp" -eq 350 ] || { echo "FAIL: working setpoint $wsp after writing 350"; exit 1; }
# Out of the map's limits (max 55.0 °C): the controller answers with an exception.
if mbpoll -m tcp -p "$port" -a 1 -t 4 -r 27 -1 127.0.0.1 700 >/dev/null 2>&1; then
  echo "FAIL: a 70.0 °C setpoint was accepted"; exit 1
fi
# The world follows: poll the PV every 200 ms until it passes 34.0 °C (time constant 5 min, 100x).
# stdbuf: mbpoll block-buffers a pipe. awk ends the pipeline as soon as it has its answer and
# mbpoll then gets SIGPIPE, so the pipeline status is awk's.
set +o pipefail
if timeout 60 stdbuf -oL mbpoll -m tcp -p "$port" -a 1 -t 4 -r 2 -c 1 -l 200 127.0.0.1 |
     awk -F'\t' '/^\[/ { if ($2 + 0 >= 340) { print "PV reached " $2; found = 1; exit 0 } } END { exit !found }'; then
  echo "PASS: mbpoll read the PV, wrote the setpoint, and the simulated chamber followed"
else
  echo "FAIL: the PV never reached 34.0 °C after the setpoint write"; exit 1
fi
