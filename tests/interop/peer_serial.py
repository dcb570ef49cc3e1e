#!/usr/bin/python3
"""Peer test: pyserial (Debian's python3-serial, not written here) writes WindSonic and CSAT3B
lines as the vendors' manuals print them into a pseudo-terminal; our driver reads the other
side (`manikin probe`). Values, status codes and checksum failures must come out as the
manuals say. Exit 77 = skipped (only when pyserial is missing)."""
import ctypes
import json
import os
import subprocess
import sys

try:
    import serial
except ImportError:
    print("SKIP: python3-serial is not installed (scripts/setup.sh installs it)")
    sys.exit(77)

manikin, data_dir = sys.argv[1], sys.argv[2]
libc = ctypes.CDLL(None)
libc.ptsname.restype = ctypes.c_char_p


def manual_lines(name):
    with open(os.path.join(data_dir, name)) as f:
        return [l.rstrip("\n") for l in f if l.strip() and not l.startswith("#")]


def run(device, lines, count):
    port = serial.Serial("/dev/ptmx", timeout=1)  # pyserial owns the instrument side
    fd = port.fileno()
    libc.grantpt(fd)
    libc.unlockpt(fd)
    slave = libc.ptsname(fd).decode()
    probe = subprocess.Popen([manikin, "probe", device, slave, "--count", str(count), "--timeout", "10", "--json"],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    # The driver reports on stderr once the port is open; wait for it before writing.
    probe.stderr.readline()
    for line in lines:
        port.write(line.encode("latin-1"))
        port.flush()
    out, err = probe.communicate(timeout=20)
    port.close()
    if probe.returncode != 0:
        print("FAIL: manikin probe", device, "exited", probe.returncode, err)
        sys.exit(1)
    return json.loads(out)


failures = []


def check(cond, what):
    print(("ok   " if cond else "FAIL ") + what)
    if not cond:
        failures.append(what)


# CSAT3B: the 12 example records of the manual (8.3.3, p. 55), then one with a flipped digit.
csat = manual_lines("csat3b_manual_examples.txt")
bad = csat[0].replace("0.08945", "0.08946")
r = run("csat3b", [l + "\r\n" for l in csat] + [bad + "\r\n"] + [csat[1] + "\r\n"], 13)
ux = [s["value"] for s in r["samples"] if s["channel"] == "ux_m_s"]
ts = [s["value"] for s in r["samples"] if s["channel"] == "sonic_temp_c"]
check(len(ux) == 13, f"CSAT3B: 13 records decoded (got {len(ux)})")
check(abs(ux[0] - 0.08945) < 1e-9 and abs(ts[0] - 19.69336) < 1e-9, "CSAT3B: first record Ux 0.08945 m/s, Ts 19.69336 C")
check(abs(ux[11] - 0.11630) < 1e-9, "CSAT3B: 12th record (signature 5cD7, mixed case) Ux 0.11630 m/s")
check(r["status"]["checksum_errors"] == 1, f"CSAT3B: the flipped digit is one signature error (got {r['status']['checksum_errors']})")

# WindSonic: the manual's example frame (section 9.1), a status code, a bad checksum.
ws = [l.replace("<STX>", "\x02").replace("<ETX>", "\x03") for l in manual_lines("windsonic_manual_examples.txt")]
frame = ws[0] + "\r\n"
def xor(payload):
    c = 0
    for ch in payload.encode():
        c ^= ch
    return c
status_payload = "Q,229,002.74,M,04,"
status_frame = "\x02" + status_payload + "\x03" + f"{xor(status_payload):02X}\r\n"
bad_frame = frame.replace("\x0316", "\x0317")
r = run("windsonic", [frame, status_frame, bad_frame, frame], 3)
speeds = [s for s in r["samples"] if s["channel"] == "air_speed_m_s"]
dirs = [s["value"] for s in r["samples"] if s["channel"] == "air_direction_deg"]
check(len(speeds) == 3, f"WindSonic: 3 frames decoded (got {len(speeds)})")
check(abs(speeds[0]["value"] - 2.74) < 1e-9 and dirs[0] == 229, "WindSonic: manual frame = 2.74 m/s from 229 deg")
check(speeds[1]["quality"] == "out_of_range", "WindSonic: status 04 (both axes failed) flags the sample")
check(r["status"]["checksum_errors"] == 1, "WindSonic: the altered checksum is one checksum error")
check(r["status"]["device_faults"] == 1, "WindSonic: status 04 counted as a device fault")

if failures:
    sys.exit(1)
print("PASS: pyserial peer lines decode as the manuals say")
