#!/usr/bin/env python3
"""One exported trial as a figure: the enclosure's air temperature against the chamber's setpoint,
and the zones' heat fluxes with their area-weighted mean (matplotlib, Debian's python3-matplotlib).

    build/bin/manikin export <campaign> /tmp/out.h5 --db manikind.db
    python3 docs/examples/plot_trial.py /tmp/out.h5 trial.png [c01-r1]

Reads the HDF5 export (docs/formats.md 1.6): the trial group's datasets and its attributes
(chamber_setpoint_temp_c), the zone table's areas for the mean. Heat flux: positive = heat lost by
the body (skin to environment).
"""
import sys

import h5py
import matplotlib

matplotlib.use("Agg")  # a file, no display needed
import matplotlib.pyplot as plt  # noqa: E402

path, out = sys.argv[1], sys.argv[2]
with h5py.File(path, "r") as f:
    trial_id = sys.argv[3] if len(sys.argv) > 3 else sorted(f["trials"].keys())[0]
    g = f["trials"][trial_id]
    t_min = g["t_s"][:] / 60.0
    air = g["air_temp_c"][:]
    setpoint = g.attrs.get("chamber_setpoint_temp_c")
    zones = f["zone_map/zone"][:]
    areas = f["zone_map/area_m2"][:]
    fluxes = [g[f"z{int(z):02d}_flux_w_m2"][:] for z in zones]
    campaign = f.attrs["campaign"]

mean = sum(a * q for a, q in zip(areas, fluxes)) / areas.sum()
fig, (top, bottom) = plt.subplots(2, 1, sharex=True, figsize=(8, 6))
top.plot(t_min, air, label="enclosure air (mean of the EE181 probes)")
if setpoint is not None:
    top.axhline(float(setpoint), color="tab:red", linestyle="--", label=f"chamber setpoint {float(setpoint):.1f} °C")
top.set_ylabel("air temperature (°C)")
top.legend(loc="best")
for q in fluxes:
    bottom.plot(t_min, q, color="0.75", linewidth=0.6)
bottom.plot(t_min, mean, color="black", linewidth=1.5, label="area-weighted mean of 35 zones")
bottom.set_xlabel("time since the manikin started (min)")
bottom.set_ylabel("heat flux (W/m², + = lost)")
bottom.legend(loc="best")
fig.suptitle(f"{campaign}, trial {trial_id}")
fig.tight_layout()
fig.savefig(out, dpi=100)
print(f"{out}: {trial_id}, {len(t_min)} rows, mean heat flux at the end {mean[-1]:.1f} W/m²")
