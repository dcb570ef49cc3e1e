#!/usr/bin/env python3
"""A standard clothing test written by physics outside manikind's code (issue 33's proof).

From ISO 9920's definitions alone: each zone's total insulation is the garment's intrinsic
insulation plus the boundary layer reduced by the clothing area factor, It_z = Icl_z + Ia_z/fcl;
a dry test at skin 35 C and air 20 C loses q_z = (T_sk - T_a)/It_z. The evaporative test is
isothermal (35 C, 40 % RH), a fully wet skin losing q_z = (p_sat(T_sk) - p_a)/Ret_z with
Ret_z = Recl_z + Rea_z/fcl. Re-dressing changes the garment's fit between replicates (a factor
common to the ensemble and one per zone, log-normal), the instruments carry one calibration error
per campaign drawn from the specs written in campaign.json (rectangular), and every sample has
sensor noise. Writes campaign.json + trials/*.csv (manikin-recording/1) and truth.json with the
values the test should find. Saturation pressure: Buck (1981), not the project's formula.

Usage: make_clothing_campaign.py --out DIR [--seed N] [--replicates 3] [--zone-map config/andi35_zone_map.csv]
"""
import argparse
import csv
import json
import math
import os
import random

LR = 16.5      # K/kPa, the Lewis relation ISO 9920 uses for im
CLO = 0.155    # m2K/W

# Nude boundary layer per region at 0.4 m/s, m2K/W (typical of manikin data: extremities lose more).
IA = {"head": 0.075, "chest": 0.095, "back": 0.095, "pelvis": 0.10, "upper_arm": 0.085, "forearm": 0.08,
      "hand": 0.065, "thigh": 0.09, "calf": 0.085, "foot": 0.08}
# Two ensembles by region (ISO 9920 Annex-like garments): intrinsic insulation m2K/W and
# intrinsic evaporative resistance m2kPa/W; 0 where the body is bare.
ENSEMBLES = {
    "workwear": {"description": "cotton coverall over briefs and T-shirt, socks and shoes", "fcl": 1.26, "fcl_given": True,
                 "icl": {"chest": 0.22, "back": 0.22, "pelvis": 0.26, "upper_arm": 0.16, "forearm": 0.14, "thigh": 0.17,
                         "calf": 0.15, "foot": 0.20},
                 "recl": {"chest": 0.030, "back": 0.030, "pelvis": 0.036, "upper_arm": 0.022, "forearm": 0.020,
                          "thigh": 0.024, "calf": 0.022, "foot": 0.045}},
    "jacket": {"description": "insulated jacket and trousers over a base layer", "fcl_given": False,
               "icl": {"chest": 0.45, "back": 0.45, "pelvis": 0.40, "upper_arm": 0.38, "forearm": 0.34, "thigh": 0.30,
                       "calf": 0.26, "foot": 0.25, "hand": 0.0},
               "recl": {"chest": 0.070, "back": 0.070, "pelvis": 0.062, "upper_arm": 0.058, "forearm": 0.052,
                        "thigh": 0.046, "calf": 0.040, "foot": 0.060}},
    # Issue 63's heavy ensembles, written only with --ensembles (the default pair keeps the seeds'
    # campaigns as they were): a down parka whose fcl follows ISO 9920's estimate, and an
    # expedition sleeping bag of about 8 clo whose fcl the lab measured.
    "parka": {"description": "down parka with hood, insulated trousers, mittens and boots", "fcl_given": False,
              "icl": {"head": 0.35, "chest": 0.95, "back": 0.95, "pelvis": 0.85, "upper_arm": 0.80, "forearm": 0.70,
                      "hand": 0.30, "thigh": 0.60, "calf": 0.50, "foot": 0.45},
              "recl": {"head": 0.060, "chest": 0.160, "back": 0.160, "pelvis": 0.145, "upper_arm": 0.135, "forearm": 0.120,
                       "hand": 0.055, "thigh": 0.100, "calf": 0.085, "foot": 0.080}},
    "bag": {"description": "expedition sleeping bag, about 8 clo, hood closed", "fcl": 2.2, "fcl_given": True,
            "icl": {"head": 0.90, "chest": 1.35, "back": 1.35, "pelvis": 1.35, "upper_arm": 1.35, "forearm": 1.35,
                    "hand": 1.35, "thigh": 1.35, "calf": 1.35, "foot": 1.35},
            "recl": {"head": 0.150, "chest": 0.220, "back": 0.220, "pelvis": 0.220, "upper_arm": 0.220, "forearm": 0.220,
                     "hand": 0.220, "thigh": 0.220, "calf": 0.220, "foot": 0.220}},
}
DEFAULT_ENSEMBLES = ["workwear", "jacket"]
# Instrument specs written into campaign.json (the draws below use the same limits).
FLUX_A, FLUX_B = 1.0, 0.03
AIR_A, SKIN_A = 0.2, 0.1
RH_A, RH_B = 1.4, 0.01


def p_sat_kpa(t_c):
    """Buck (1981) over water."""
    return 0.61121 * math.exp((18.678 - t_c / 234.5) * (t_c / (257.14 + t_c)))


def segment_of(region):
    for seg in IA:
        if region == seg or region.startswith(seg + "_"):
            return seg
    raise SystemExit(f"no boundary layer for region {region}")


def read_zones(path):
    with open(path, newline="") as f:
        return [dict(r, zone=int(r["zone"]), area_m2=float(r["area_m2"])) for r in csv.DictReader(f)]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", required=True)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--replicates", type=int, default=3)
    ap.add_argument("--zone-map", default=os.path.join(os.path.dirname(__file__), "..", "..", "config", "andi35_zone_map.csv"))
    ap.add_argument("--fit-sd", type=float, default=0.02, help="re-dressing: log-sd of the ensemble's fit factor")
    ap.add_argument("--zone-fit-sd", type=float, default=0.03, help="re-dressing: log-sd per zone")
    ap.add_argument("--ensembles", default=",".join(DEFAULT_ENSEMBLES),
                    help="which ensembles, comma-separated, of " + ", ".join(ENSEMBLES))
    a = ap.parse_args()
    chosen = [e for e in a.ensembles.split(",") if e]
    for e in chosen:
        if e not in ENSEMBLES:
            raise SystemExit(f"--ensembles: unknown ensemble {e!r} (known: {', '.join(ENSEMBLES)})")
    rng = random.Random(a.seed)
    zones = read_zones(a.zone_map)
    area = sum(z["area_m2"] for z in zones)
    seg = {z["zone"]: segment_of(z["segment"]) for z in zones}

    # One calibration error per campaign (rectangular within each spec), shared by every trial.
    err = {"flux_a": rng.uniform(-1, 1) * FLUX_A, "flux_b": rng.uniform(-1, 1) * FLUX_B,
           "air": rng.uniform(-1, 1) * AIR_A, "skin": rng.uniform(-1, 1) * SKIN_A, "rh": rng.uniform(-1, 1)}

    def parallel(it):
        return 1.0 / sum(z["area_m2"] / area / it[z["zone"]] for z in zones)

    def ens_values(name):
        """Per zone It and Ret (truth, mean fit) for an ensemble or the nude manikin, and its fcl."""
        if name == "nude":
            return {z["zone"]: IA[seg[z["zone"]]] for z in zones}, {z["zone"]: IA[seg[z["zone"]]] / LR / 0.6 for z in zones}, 1.0
        e = ENSEMBLES[name]

        def at(fcl):
            it = {z["zone"]: e["icl"].get(seg[z["zone"]], 0.0) + IA[seg[z["zone"]]] / fcl for z in zones}
            ret = {z["zone"]: e["recl"].get(seg[z["zone"]], 0.0) + IA[seg[z["zone"]]] / LR / 0.6 / fcl for z in zones}
            return it, ret
        if e["fcl_given"]:
            fcl = e["fcl"]
        else:
            # The garment follows ISO 9920's estimate fcl = 1 + 0.28 Icl (clo), Icl = It - Ia/fcl
            # of the whole ensemble (parallel), so the estimate the tool makes is the truth here.
            ia = parallel({z["zone"]: IA[seg[z["zone"]]] for z in zones})
            fcl = 1.0
            for _ in range(50):
                fcl = 1.0 + 0.28 * (parallel(at(fcl)[0]) - ia / fcl) / CLO
        it, ret = at(fcl)
        return it, ret, fcl

    trials, truth = [], {}
    os.makedirs(os.path.join(a.out, "trials"), exist_ok=True)
    case = 0
    for name in ["nude"] + chosen:
        it, ret, fcl = ens_values(name)
        for test in ("insulation", "evaporative"):
            case += 1
            t_sk, t_a, rh = (35.0, 20.0, 50.0) if test == "insulation" else (35.0, 35.0, 40.0)
            p_a = rh / 100.0 * p_sat_kpa(t_a)
            for r in range(1, a.replicates + 1):
                fit = math.exp(rng.gauss(0.0, a.fit_sd)) if name != "nude" else 1.0
                rows = []
                zone_q = {}
                for z in zones:
                    zf = math.exp(rng.gauss(0.0, a.zone_fit_sd)) if name != "nude" else 1.0
                    if test == "insulation":
                        # The garment's part scales with the fit; the boundary layer does not.
                        e_icl = it[z["zone"]] - IA[seg[z["zone"]]] / fcl
                        zone_q[z["zone"]] = (t_sk - t_a) / (e_icl * fit * zf + IA[seg[z["zone"]]] / fcl)
                    else:
                        e_recl = ret[z["zone"]] - IA[seg[z["zone"]]] / LR / 0.6 / fcl
                        zone_q[z["zone"]] = (p_sat_kpa(t_sk) - p_a) / (e_recl * fit * zf + IA[seg[z["zone"]]] / LR / 0.6 / fcl)
                tid = f"c{case:02d}-r{r}"
                for k in range(141):  # 35 min at 15 s (the last 30 min are the steady window)
                    row = {"t_s": 15.0 * k,
                           "air_temp_c": t_a + err["air"] + rng.gauss(0, 0.02),
                           "air_rh_pct": rh + err["rh"] * (RH_A + RH_B * rh) + rng.gauss(0, 0.2),
                           "air_speed_m_s": 0.4 + rng.gauss(0, 0.02)}
                    for z in zones:
                        row[f"z{z['zone']:02d}_skin_c"] = t_sk + err["skin"] + rng.gauss(0, 0.004)
                    for z in zones:
                        q = zone_q[z["zone"]]
                        row[f"z{z['zone']:02d}_flux_w_m2"] = q + err["flux_a"] + err["flux_b"] * abs(q) + rng.gauss(0, 1.0)
                    rows.append(row)
                with open(os.path.join(a.out, "trials", tid + ".csv"), "w", newline="") as f:
                    w = csv.DictWriter(f, fieldnames=list(rows[0]))
                    w.writeheader()
                    for row in rows:
                        w.writerow({k: repr(v) for k, v in row.items()})
                trials.append({"id": tid, "case": case, "replicate": r, "skin_setpoint_c": t_sk,
                               "wet": test == "evaporative", "ensemble": name, "test": test,
                               "chamber_setpoint": {"temp_c": t_a, "rh_pct": rh}})
        # Truth, by the definitions (mean fit, no instrument error).
        f = {z["zone"]: z["area_m2"] / area for z in zones}
        q_dry = {zz: 15.0 / it[zz] for zz in it}
        p_a_e = 0.40 * p_sat_kpa(35.0)
        q_evap = {zz: (p_sat_kpa(35.0) - p_a_e) / ret[zz] for zz in ret}
        truth[name] = {"fcl": fcl,
                       "It_par": 15.0 / sum(f[zz] * q_dry[zz] for zz in f),
                       "It_ser": sum(f[zz] * it[zz] for zz in f),
                       "Ret_par": (p_sat_kpa(35.0) - p_a_e) / sum(f[zz] * q_evap[zz] for zz in f),
                       "Ret_ser": sum(f[zz] * ret[zz] for zz in f)}
    for name in chosen:
        t, n = truth[name], truth["nude"]
        t["Icle_par"] = t["It_par"] - n["It_par"]
        t["Icl_par"] = t["It_par"] - n["It_par"] / t["fcl"]
        t["Recl_par"] = t["Ret_par"] - n["Ret_par"] / t["fcl"]
    for name in truth:
        truth[name]["im"] = truth[name]["It_par"] / (LR * truth[name]["Ret_par"])
    doc = {"format": "manikin-recording/1", "name": f"clothing-proof-{a.seed}", "zone_map": "andi35",
           "instruments": {"heat_flux_w_m2": {"accuracy": FLUX_A, "accuracy_of_reading": FLUX_B},
                           "air_temp_c": {"accuracy": AIR_A}, "skin_temp_c": {"accuracy": SKIN_A},
                           "air_rh_pct": {"accuracy": RH_A, "accuracy_of_reading": RH_B}},
           "ensembles": {n: ({"description": ENSEMBLES[n]["description"], "fcl": ENSEMBLES[n]["fcl"]} if ENSEMBLES[n]["fcl_given"]
                             else {"description": ENSEMBLES[n]["description"]}) for n in chosen},
           "trials": trials}
    with open(os.path.join(a.out, "campaign.json"), "w") as f:
        json.dump(doc, f, indent=1)
    with open(os.path.join(a.out, "truth.json"), "w") as f:
        json.dump(truth, f, indent=1)


if __name__ == "__main__":
    main()
