#!/usr/bin/python3
"""Peer test: a Modbus TCP server written with Debian's python3-pymodbus (not written here) acts
as the chamber controller with the shipped register map (Eurotherm 3200: unit 1 temperature,
unit 2 humidity, x10 int16). Our Modbus driver (`manikin probe chamber`) must write setpoints
scaled as documented, read the process values back, report an exception response, and survive
the server going away. Exit 77 = skipped (only when pymodbus cannot be imported)."""
import json
import os
import socket
import subprocess
import sys
import tempfile
import threading

try:
    from pymodbus.datastore import (ModbusSequentialDataBlock, ModbusServerContext, ModbusSlaveContext,
                                    ModbusSparseDataBlock)
    from pymodbus.server import StartTcpServer, ServerStop
except ImportError as e:
    print(f"SKIP: pymodbus is not importable ({e}); scripts/setup.sh installs python3-pymodbus and python3-serial-asyncio")
    sys.exit(77)

manikin = sys.argv[1]
with socket.socket() as s:
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]

# Register images: 40 holding registers per unit, addresses as in config/chamber_registers.toml.
temp = ModbusSlaveContext(hr=ModbusSequentialDataBlock(0, [0] * 40), zero_mode=True)
rh = ModbusSlaveContext(hr=ModbusSequentialDataBlock(0, [0] * 40), zero_mode=True)
temp.setValues(3, 1, [231])   # PV 23.1 °C
temp.setValues(3, 5, [231])
rh.setValues(3, 1, [456])     # PV 45.6 %


class OneRegisterAtATime(ModbusSequentialDataBlock):
    """A device that answers ILLEGAL DATA ADDRESS to any read of more than one register (some
    controllers and gateways do): our driver must fall back from its block reads."""

    def validate(self, address, count=1):
        return count == 1 and super().validate(address, count)


single = ModbusSlaveContext(hr=OneRegisterAtATime(0, [0] * 40), zero_mode=True)
single.setValues(3, 10, [123])
single.setValues(3, 11, [-45 & 0xFFFF])
# A device with only registers 10, 11 and 20: pymodbus' sparse block answers ILLEGAL DATA ADDRESS
# to any read that touches 12..19, so a read bridged across them must fall back to runs.
sparse = ModbusSlaveContext(hr=ModbusSparseDataBlock({10: 201, 11: 202, 20: 203}), zero_mode=True)
context = ModbusServerContext(slaves={1: temp, 2: rh, 3: single, 4: sparse}, single=False)
server = threading.Thread(target=StartTcpServer, kwargs={"context": context, "address": ("127.0.0.1", port)}, daemon=True)
server.start()
# Wait until it accepts connections (a connect attempt, not a sleep).
for _ in range(200):
    try:
        socket.create_connection(("127.0.0.1", port), timeout=0.1).close()
        break
    except OSError:
        threading.Event().wait(0.05)

failures = []


def check(cond, what):
    print(("ok   " if cond else "FAIL ") + what)
    if not cond:
        failures.append(what)


def probe(*args, map_file=None, exit_code=0):
    cmd = [manikin, "probe", "chamber", "--port", str(port), "--timeout", "1", "--json"] + list(args)
    if map_file:
        cmd += ["--map", map_file]
    out = subprocess.run(cmd, capture_output=True, text=True, timeout=30)
    check(out.returncode == exit_code, f"probe {' '.join(args)} exits {exit_code} (got {out.returncode})")
    if out.returncode != 0:
        print(out.stderr)
    doc = json.loads(out.stdout)
    # A refused write (exit 4, docs/cli.md) carries the probe's readings in the error's details.
    return doc["error"]["details"] if "error" in doc else doc


# Both units' reads sent before either reply is read (the Messaging on TCP/IP guide's pipelining):
# pymodbus answers them in order, and each value lands on its own channel.
r = probe("--in-flight", "4")
pv = {s["channel"]: s for s in r["samples"]}
check(r["status"]["frames"] == 2 and r["status"]["comm_errors"] == 0 and r["status"]["timeouts"] == 0,
      f"--in-flight 4: both units answered, no error (got {r['status']})")
check(abs(pv["air_temp_pv_c"]["value"] - 23.1) < 1e-9 and abs(pv["air_rh_pv_pct"]["value"] - 45.6) < 1e-9,
      f"--in-flight 4: PVs 23.1 °C and 45.6 % (got {r['samples']})")

r = probe("--write", "air_temp_remote_setpoint_c=35.5", "--write", "air_rh_remote_setpoint_pct=40")
check(all(w["ok"] for w in r["writes"]), "setpoints written")
check(temp.getValues(3, 26, 1) == [355], f"Rm.SP arrived x10 at unit 1 address 26 (got {temp.getValues(3, 26, 1)})")
check(rh.getValues(3, 26, 1) == [400], f"RH Rm.SP arrived x10 at unit 2 address 26 (got {rh.getValues(3, 26, 1)})")
pv = {s["channel"]: s for s in r["samples"]}
check(abs(pv["air_temp_pv_c"]["value"] - 23.1) < 1e-9, "temperature PV read back as 23.1 °C")
check(abs(pv["air_rh_pv_pct"]["value"] - 45.6) < 1e-9, "humidity PV read back as 45.6 %")

r = probe("--write", "air_temp_remote_setpoint_c=80", exit_code=4)
check(not r["writes"][0]["ok"] and "55" in r["writes"][0]["error"], "80 °C refused by the map's limit before sending")
check(temp.getValues(3, 26, 1) == [355], "the refused setpoint never reached the controller")

# An exception response: a register the controller does not have (address 500).
with tempfile.NamedTemporaryFile("w", suffix=".toml", delete=False) as f:
    f.write('family = "test"\n[units]\ntemperature = 1\n[[registers]]\nname = "missing_c"\nunit_id = "temperature"\n'
            'address = 500\ntype = "int16"\nscale = 0.1\naccess = "read"\n')
    bad_map = f.name
r = probe(map_file=bad_map)
check(r["status"]["exceptions"] == 1, f"exception response counted (got {r['status']})")
check(r["samples"][0]["quality"] == "comm_error", "the sample is flagged comm_error")
os.unlink(bad_map)

# Contiguous registers are read in one request; a device that refuses that is read point by point.
with tempfile.NamedTemporaryFile("w", suffix=".toml", delete=False) as f:
    f.write('family = "test"\n[units]\nsingle = 3\n'
            '[[registers]]\nname = "a_c"\nunit_id = "single"\naddress = 10\ntype = "int16"\nscale = 0.1\naccess = "read"\n'
            '[[registers]]\nname = "b_c"\nunit_id = "single"\naddress = 11\ntype = "int16"\nscale = 0.1\naccess = "read"\n')
    single_map = f.name
r = probe(map_file=single_map)
vals = {s["channel"]: s for s in r["samples"]}
check(vals["a_c"]["quality"] == "good" and abs(vals["a_c"]["value"] - 12.3) < 1e-9, f"register 10 read alone: 12.3 (got {vals['a_c']})")
check(vals["b_c"]["quality"] == "good" and abs(vals["b_c"]["value"] + 4.5) < 1e-9, f"register 11 read alone: -4.5 (got {vals['b_c']})")
check(r["status"]["exceptions"] == 1, f"the refused two-register request counted once (got {r['status']})")
os.unlink(single_map)

# Registers 10, 11 and 20 of the sparse device: with --max-gap 16 one request spans 10..20, the
# device refuses the unused 12..19, and the driver reads the runs 10-11 and 20 instead (two
# requests, not three singles); with --max-gap 0 it never asks for the hole.
with tempfile.NamedTemporaryFile("w", suffix=".toml", delete=False) as f:
    f.write('family = "test"\n[units]\nsparse = 4\n' + ''.join(
        f'[[registers]]\nname = "r{a}_c"\nunit_id = "sparse"\naddress = {a}\ntype = "int16"\nscale = 0.1\naccess = "read"\n'
        for a in (10, 11, 20)))
    sparse_map = f.name
for gap, exceptions, frames, in_flight in (("16", 1, 2, "1"), ("0", 0, 2, "1"), ("16", 1, 2, "4")):
    r = probe("--max-gap", gap, "--in-flight", in_flight, map_file=sparse_map)
    vals = {s["channel"]: s for s in r["samples"]}
    check(all(vals[f"r{a}_c"]["quality"] == "good" and abs(vals[f"r{a}_c"]["value"] - v) < 1e-9
              for a, v in ((10, 20.1), (11, 20.2), (20, 20.3))),
          f"--max-gap {gap}: registers 10, 11 and 20 read as 20.1, 20.2, 20.3 (got {r['samples']})")
    check(r["status"]["exceptions"] == exceptions and r["status"]["frames"] == frames,
          f"--max-gap {gap}: {exceptions} refused request(s), {frames} answered (got {r['status']})")
    if gap == "16":
        check("contiguous runs" in r["status"]["last_error"], f"the fallback is named (got {r['status']['last_error']!r})")
os.unlink(sparse_map)

# The server goes away: connection refused is a comm error, not a crash.
ServerStop()
server.join(timeout=5)
r = probe()
check(r["status"]["comm_errors"] >= 1 and all(s["quality"] == "comm_error" for s in r["samples"]),
      "server gone: every point comm_error, counted")

if failures:
    sys.exit(1)
print("PASS: our Modbus driver against a pymodbus controller")
