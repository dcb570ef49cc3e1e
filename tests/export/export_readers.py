#!/usr/bin/python3
"""The tools labs read exports with, on a campaign the daemon recorded (issue 16).

    export_readers.py MANIKIN h5py|pandas|octave

h5py:   every dataset of the HDF5 export equals the CSV export's column and the database's
        samples (read with Python's own sqlite3, not our code); units and provenance attributes.
pandas: docs/examples/pandas_trial_table.py runs against the database; its numbers equal the
        CSV export's.
octave: docs/examples/octave_read_hdf5.m runs in GNU Octave on the HDF5 export; its numbers
        equal h5py's.
Exit 77 (skipped) only when the tool itself is not installed.
"""
import csv
import json
import math
import os
import re
import shutil
import sqlite3
import subprocess
import sys
import tempfile

manikin, mode = sys.argv[1], sys.argv[2]
repo = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def skip(why):
    print(f"SKIP: {why}")
    sys.exit(77)


def fail(why):
    print(f"FAIL: {why}")
    sys.exit(1)


if mode == "h5py":
    try:
        import h5py
    except ImportError:
        skip("python3-h5py is not installed (scripts/setup.sh --tests installs it)")
elif mode == "pandas":
    try:
        import pandas  # noqa: F401
    except ImportError:
        skip("python3-pandas is not installed (scripts/setup.sh --tests installs it)")
elif mode == "octave":
    if not shutil.which("octave-cli"):
        skip("GNU Octave is not installed (scripts/setup.sh --tests installs it)")
    try:
        import h5py
    except ImportError:
        skip("python3-h5py is not installed")
else:
    fail(f"unknown mode {mode}")

work = tempfile.mkdtemp(prefix="manikind-export-readers-")
try:
    subprocess.run([manikin, "demo", "--cases", "2", "--replicates", "1", "--out", work], check=True,
                   stdout=subprocess.DEVNULL)
    db = os.path.join(work, "manikind.db")
    # Two lab-notebook entries, as the daemon stores them (`manikin note`): one on the campaign,
    # one on its first trial; every export must carry both.
    rw = sqlite3.connect(db)
    (campaign_id,) = rw.execute("SELECT id FROM campaigns").fetchone()
    (first_trial,) = rw.execute("SELECT min(id) FROM trials WHERE state = 'done'").fetchone()
    rw.execute("INSERT INTO notes (campaign_id, trial_id, utc_ns, author, kind, text) VALUES (?, NULL, 1, 'ana', 'operator', 'Ana ran it')",
               (campaign_id,))
    rw.execute("INSERT INTO notes (campaign_id, trial_id, utc_ns, author, kind, text) VALUES (?, ?, 2, 'bo', 'garment', 'sleeve torn, zone 12')",
               (campaign_id, first_trial))
    rw.commit()
    rw.close()
    con = sqlite3.connect(f"file:{db}?mode=ro", uri=True)
    (campaign,) = con.execute("SELECT name FROM campaigns").fetchone()
    subprocess.run([manikin, "export", "--db", db, campaign, os.path.join(work, "csv")], check=True,
                   stdout=subprocess.DEVNULL)
    h5_path = os.path.join(work, "campaign.h5")
    subprocess.run([manikin, "export", "--db", db, campaign, h5_path, "--format", "hdf5"], check=True,
                   stdout=subprocess.DEVNULL)

    def csv_columns(trial_id):
        with open(os.path.join(work, "csv", "trials", trial_id + ".csv"), newline="") as f:
            rows = list(csv.reader(f))
        return {name: [r[i] for r in rows[1:]] for i, name in enumerate(rows[0])}

    with open(os.path.join(work, "csv", "campaign.json")) as f:
        notes = json.load(f).get("notes", [])
    if [(n["author"], n["kind"], n["text"], "trial" in n) for n in notes] != [
            ("ana", "operator", "Ana ran it", False), ("bo", "garment", "sleeve torn, zone 12", True)]:
        fail(f"campaign.json notes: {notes!r}")

    if mode == "h5py":
        checked = 0
        with h5py.File(h5_path, "r") as f:
            if f.attrs["format"] != "manikin-hdf5/1":
                fail(f"format attribute {f.attrs['format']!r}")
            got = [tuple(x.decode() for x in row) for row in zip(f["notes/author"][:], f["notes/kind"][:], f["notes/text"][:])]
            if got != [("ana", "operator", "Ana ran it"), ("bo", "garment", "sleeve torn, zone 12")]:
                fail(f"HDF5 /notes: {got!r}")
            if f["notes/trial"][1].decode() != notes[1]["trial"] or f["notes/trial"][0] != b"":
                fail(f"HDF5 /notes/trial: {f['notes/trial'][:]!r}")
            if len(f.attrs["config_sha256"]) != 64 or not f.attrs["program"].startswith("manikind "):
                fail("provenance attributes missing")
            units = dict(con.execute(
                "SELECT d.name || '.' || c.name, c.unit FROM channels c JOIN devices d ON d.id = c.device_id"))
            for trial_id, group in f["trials"].items():
                cols = csv_columns(trial_id)
                t0 = con.execute(
                    "SELECT e.mono_ns, e.trial_id FROM events e JOIN trials t ON t.id = e.trial_id "
                    "WHERE e.kind = 'stage' AND e.message = 'acquiring' AND t.replicate = ? AND "
                    "json_extract((SELECT conditions_json FROM cases WHERE id = t.case_id), '$.id') = ?",
                    (int(group.attrs["replicate"]), int(group.attrs["case"]))).fetchone()
                if t0 is None:
                    fail(f"{trial_id}: no acquiring event for case {group.attrs['case']}")
                t0_mono, db_trial = t0
                # The trial group says what was asked: the chamber's setpoints, as the case stored them.
                asked = con.execute(
                    "SELECT json_extract(conditions_json, '$.chamber_temp_c'), json_extract(conditions_json, '$.chamber_rh_pct') "
                    "FROM cases WHERE id = (SELECT case_id FROM trials WHERE id = ?)", (db_trial,)).fetchone()
                for attr, want in zip(("chamber_setpoint_temp_c", "chamber_setpoint_rh_pct"), asked):
                    if attr not in group.attrs or abs(float(group.attrs[attr]) - float(want)) > 1e-9:
                        fail(f"{trial_id}: attribute {attr} {group.attrs.get(attr)!r}, the case asked {want!r}")
                data = {name: dataset[:] for name, dataset in group.items()}  # one read per dataset
                for name, values in data.items():
                    if name.endswith(".q") or name in ("utc_ns",):
                        continue
                    if name not in cols:
                        fail(f"{trial_id}/{name}: in the HDF5 file, not in the CSV")
                    for i, text in enumerate(cols[name]):
                        value = float(text) if text else math.nan
                        if not (value == values[i] or (math.isnan(value) and math.isnan(values[i]))):
                            fail(f"{trial_id}/{name} row {i}: CSV {text!r}, HDF5 {values[i]!r}")
                        checked += 1
                    if name in units and group[name].attrs["unit"] != units[name]:
                        fail(f"{trial_id}/{name}: unit {group[name].attrs['unit']!r}, database {units[name]!r}")
                # Every sample on the grid, straight from the database.
                for column, mono_ns, value, quality in con.execute(
                        "SELECT d.name || '.' || c.name, s.mono_ns, s.value, s.quality FROM samples s "
                        "JOIN channels c ON c.id = s.channel_id JOIN devices d ON d.id = c.device_id "
                        "WHERE s.trial_id = ? AND s.mono_ns >= ? AND (s.mono_ns - ?) % 5000000000 = 0",
                        (db_trial, t0_mono, t0_mono)):
                    row = (mono_ns - t0_mono) // 5000000000
                    if row >= len(data["t_s"]):
                        continue
                    if data[column][row] != value or data[column + ".q"][row] != quality:
                        fail(f"{trial_id}/{column} row {row}: HDF5 {data[column][row]!r}, database {value!r}")
                    checked += 1
        if checked < 200000:
            fail(f"only {checked} values compared")
        print(f"h5py: {checked} values equal to the CSV export and the database")

        # The plotting example of the README (docs/examples/plot_trial.py, matplotlib) on this export.
        try:
            import matplotlib  # noqa: F401
        except ImportError:
            fail("python3-matplotlib is not installed (scripts/setup.sh --tests installs it): the README's plotting example cannot run")
        png = os.path.join(work, "trial.png")
        run = subprocess.run(["/usr/bin/python3", os.path.join(repo, "docs", "examples", "plot_trial.py"), h5_path, png],
                             capture_output=True, text=True)
        print(run.stdout, run.stderr)
        if run.returncode != 0 or not os.path.exists(png):
            fail("the plotting example failed")
        with open(png, "rb") as f:
            head = f.read(8)
        if head != b"\x89PNG\r\n\x1a\n" or os.path.getsize(png) < 20000:
            fail(f"the plotting example wrote no real figure ({os.path.getsize(png)} bytes)")

    elif mode == "pandas":
        run = subprocess.run(["/usr/bin/python3", os.path.join(repo, "docs", "examples", "pandas_trial_table.py"), db],
                             capture_output=True, text=True)
        print(run.stdout, run.stderr)
        if run.returncode != 0:
            fail("the pandas example failed")
        first_trial = sorted(os.listdir(os.path.join(work, "csv", "trials")))[0][:-4]
        cols = csv_columns(first_trial)
        t = [float(x) for x in cols["t_s"]]
        probe = [float(x) for x, ts in zip(cols["datalogger.ee181_1.air_temp_c"], t) if ts > max(t) - 1800]
        expected = f"probe 1 air temperature, last 30 min: {sum(probe) / len(probe):.3f} °C"
        if expected not in run.stdout:
            fail(f"expected the line '{expected}'")
        if len(re.findall(r"^case \d+: Q_WB = ", run.stdout, re.M)) != 2:
            fail("expected a result line per case")

    elif mode == "octave":
        run = subprocess.run(["octave-cli", "--no-gui", "--quiet",
                              os.path.join(repo, "docs", "examples", "octave_read_hdf5.m"), h5_path],
                             capture_output=True, text=True)
        print(run.stdout, run.stderr)
        if run.returncode != 0:
            fail("the Octave example failed")
        with h5py.File(h5_path, "r") as f:
            r = f["results"]
            for i in range(len(r["case"])):
                line = (f"case {r['case'][i]}: Q_WB = {r['q_wb_w_m2'][i]:.2f} ± {r['u95_w_m2'][i]:.2f} W/m² "
                        f"(n = {r['n_replicates'][i]})")
                if line not in run.stdout:
                    fail(f"expected the line '{line}'")
            first = sorted(f["trials"].keys())[0]
            g = f["trials"][first]
            t = g["t_s"][:]
            probe = g["datalogger.ee181_1.air_temp_c"][:][t > t.max() - 1800]
            line = f"probe 1 air temperature, last 30 min: {probe.mean():.3f} °C"
            if line not in run.stdout or f"{len(t)} rows" not in run.stdout:
                fail(f"expected the line '{line}' and {len(t)} rows")
            # Every dataset of every trial as Octave's load gives it, printed to 17 digits (a
            # double's round trip), against the CSV export: names with '.' and '-' become '_'.
            dump = os.path.join(work, "octave-dump.txt")
            script = (
                f"s = load('{h5_path}'); f = fopen('{dump}', 'w'); trials = fieldnames(s.trials);"
                "for i = 1:numel(trials), g = s.trials.(trials{i}); names = fieldnames(g);"
                " for j = 1:numel(names), v = double(g.(names{j}));"
                "  fprintf(f, '%s %s', trials{i}, names{j}); fprintf(f, ' %.17g', v); fprintf(f, '\\n'); end; end;"
                "fclose(f);")
            run = subprocess.run(["octave-cli", "--no-gui", "--quiet", "--eval", script], capture_output=True, text=True)
            if run.returncode != 0:
                print(run.stdout, run.stderr)
                fail("Octave could not load every dataset")
            checked = 0
            octave_names = {}
            csv_of = {trial_id: csv_columns(trial_id) for trial_id in f["trials"]}
            for trial_id, cols in csv_of.items():
                for name in cols:
                    if name != "utc":
                        octave_names[(trial_id.replace("-", "_"), re.sub(r"[.\-]", "_", name))] = (trial_id, name)
            seen = set()
            with open(dump) as d:
                for row in d:
                    parts = row.split()
                    key = (parts[0], parts[1])
                    if key not in octave_names:
                        continue
                    trial_id, name = octave_names[key]
                    values = [float(x) for x in parts[2:]]
                    # An empty CSV cell is NaN in a value dataset, 255 in a quality dataset.
                    expected = [(float(x) if x else (255.0 if name.endswith(".q") else math.nan))
                                for x in csv_of[trial_id][name]]
                    if len(values) != len(expected):
                        fail(f"Octave {key}: {len(values)} values, CSV {len(expected)}")
                    for a, b in zip(values, expected):
                        if not (a == b or (math.isnan(a) and math.isnan(b))):
                            fail(f"Octave {key}: {a!r}, CSV {b!r}")
                        checked += 1
                    seen.add(key)
            missing = set(octave_names) - seen
            if missing:
                fail(f"Octave's load gave no {sorted(missing)[:5]}")
            print(f"octave: {checked} values of {len(seen)} datasets equal to the CSV export")
    print("ok")
finally:
    shutil.rmtree(work, ignore_errors=True)
