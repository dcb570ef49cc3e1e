#!/usr/bin/env python3
"""A recorded trial as a pandas table, straight from the daemon's database.

    python3 docs/examples/pandas_trial_table.py manikind.db

The views (docs/recorder.md, "Reading the database") do the joins: trial_info names each trial,
trial_table has one row per 5-s step and a column per channel ("<device>.<channel>", with
"<device>.<channel>.q" its quality), case_results holds the latest analysis per case.
Heat flux: positive = heat lost by the body (skin to environment).
"""
import sqlite3
import sys

import pandas as pd

db = sys.argv[1] if len(sys.argv) > 1 else "manikind.db"
con = sqlite3.connect(f"file:{db}?mode=ro", uri=True)  # read-only: safe beside a running daemon

trials = pd.read_sql_query(
    "SELECT trial_id, campaign, case_number, replicate FROM trial_info WHERE state = 'done' ORDER BY trial_id", con)
first = trials.iloc[0]
table = pd.read_sql_query("SELECT * FROM trial_table WHERE trial_id = ? AND t_s >= 0 ORDER BY t_s", con,
                          params=(int(first.trial_id),))
table["utc"] = pd.to_datetime(table["utc_ns"], unit="ns", utc=True)

# The steady-state window of the paper: the last 30 min of the trial.
last_30_min = table[table["t_s"] > table["t_s"].max() - 1800]
flux_columns = [c for c in table.columns if c.endswith(".heat_flux_w_m2")]
print(f"trial {first.trial_id} (case {first.case_number}, replicate {first.replicate}): "
      f"{len(table)} rows, {len(flux_columns)} zone heat fluxes, from {table['utc'].iloc[0]}")
print(f"probe 1 air temperature, last 30 min: {last_30_min['datalogger.ee181_1.air_temp_c'].mean():.3f} °C")
print(f"probe 2 air temperature, last 30 min: {last_30_min['datalogger.ee181_2.air_temp_c'].mean():.3f} °C")

results = pd.read_sql_query(
    "SELECT case_number, n_replicates, q_wb_w_m2, u95_w_m2 FROM case_results ORDER BY case_number", con)
for row in results.itertuples():
    print(f"case {row.case_number}: Q_WB = {row.q_wb_w_m2:.2f} ± {row.u95_w_m2:.2f} W/m² (n = {row.n_replicates})")
