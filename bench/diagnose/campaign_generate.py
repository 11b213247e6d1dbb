#!/usr/bin/env python3
"""The "campaign" record: nine CHO fed-batches (11 states) simulated from
models/diagnose/campaign/truth.gbm (lactate production and its glucose-repressed
uptake) by scipy Radau (rtol 1e-11, atol 1e-13), restarted at every feed change.

Writes (defaults):
  models/diagnose/campaign/data/campaign.csv         the record gbc reads
  models/diagnose/campaign/data/campaign_truth.json  true consts, starts, feed programmes, noise
  models/diagnose/campaign/data/campaign_clean.csv   the noise-free truth at every record row

Each batch (10-14 days, harvest on the day's sampling): inoculation at t = 0 (Xv 0.3-0.5
1e6 cells/mL, GLC 30-40, GLN 4-6, ASN 3-5 mM, V 1.8-2.2 L, ...). From day 2 or 3 a bolus of
feed medium every day at 8-12 h of the day's clock, 0.5 h long, 2.5-4.5 % of the volume
(a per-batch share). Glucose shots: at each off-line sample the operator reads the glucose
(with its assay noise) and, below a per-batch threshold (2-10 mM), adds 2.5 M glucose to
reach a per-batch target (at least the threshold + 6 and 10 mM, at most 25 mM) in a
0.25 h shot starting 0.25 h after the sample. Batches with a low threshold run out of
glucose between samples, which is when the cells take up lactate. The uptake is nearly
zero-order down to K_GLC = 0.1 mM: once the glucose runs out the feed's glucose is consumed
within minutes, the glucose balance relaxing at up to about 11 1/h against 0.003-0.005 1/h
for the slowest balances (stiff over the 250-345 h of a batch). The last batch, the
held-out C9, is the campaign's lean-glucose run (threshold 2-3 mM), so that the held-out
score sees the lactate switch.

Records: every input change is a row (F, F_G); on-line every 3 h (jittered by 0.1 h, on
a 3-minute clock): viable cells Xv from a capacitance probe (5 % + 0.05) and the volume V
from the scale (0.3 % + 2 mL); off-line samples every 6-12 h (jittered by up to 1.5 h;
5 % skipped, never the first or the last): Xv and Xd from the cell counter (4 % + 0.02,
5 % + 0.01), GLC, GLN, GLU, LAC, AMM from the bioanalyser (3 % + 0.05 mM, GLN/GLU 0.02),
ALA and ASN by amino-acid HPLC at 60 % of the samples (5 % + 0.02 mM), the titer MAb from
day 2 (5 % + 5 mg/L); 4 % of these single cells missing. Noise log-normal plus the
absolute floor, clipped at 0, 4 significant digits. The first row (t = 0) measures all.
The held-out batch is C9 (lean glucose, above).

numpy + scipy + sympy and a built gbc (target/release/gbc, for the truth's IR);
deterministic by --seed.
"""

import argparse
import math
import sys

import numpy as np

from common import ROOT, gbmlib, noisy, on_clock, programme, rel, run_truth, write_clean, write_json, write_record

CASE = ROOT / "models/diagnose/campaign"
STATES = ["Xv", "Xd", "GLC", "GLN", "GLU", "LAC", "AMM", "ALA", "ASN", "MAb", "V"]
INPUTS = ["F", "F_G"]
CELLS = "1e6 cells/mL"
UNITS = {"t": "h", "F": "L/h", "F_G": "L/h", "Xv": CELLS, "Xd": CELLS, "GLC": "mM", "GLN": "mM",
         "GLU": "mM", "LAC": "mM", "AMM": "mM", "ALA": "mM", "ASN": "mM", "MAb": "mg/L", "V": "L"}
OFFLINE = {  # relative (log-normal) noise, absolute floor
    "Xv": (0.04, 0.02), "Xd": (0.05, 0.01), "GLC": (0.03, 0.05), "GLN": (0.03, 0.02),
    "GLU": (0.03, 0.02), "LAC": (0.03, 0.05), "AMM": (0.03, 0.05), "ALA": (0.05, 0.02),
    "ASN": (0.05, 0.02), "MAb": (0.05, 5.0),
}
ONLINE = {"Xv": (0.05, 0.05), "V": (0.003, 0.002)}
CLOCK = 0.05
FEED_CLOCK = 0.25


class Programme:
    """The two pumps' changes: {time: [F, F_G]} (a value of None keeps the pump)."""

    def __init__(self):
        self.changes = {0.0: [0.0, 0.0]}

    def set(self, t, k, value):
        self.changes.setdefault(t, [None, None])[k] = value

    def experiment(self):
        times = sorted(self.changes)
        held, rows = [0.0, 0.0], []
        for t in times:
            held = [v if v is not None else h for v, h in zip(self.changes[t], held)]
            rows.append(list(held))
        return programme(times, rows)


def batch(model, name, rng, lean=False):
    days = int(rng.integers(10, 15))
    y0 = {"Xv": round(rng.uniform(0.3, 0.5), 3), "Xd": round(rng.uniform(0.01, 0.03), 3),
          "GLC": round(rng.uniform(30, 40), 1), "GLN": round(rng.uniform(4, 6), 2),
          "GLU": round(rng.uniform(0.5, 1.0), 2), "LAC": round(rng.uniform(0.5, 2.0), 2),
          "AMM": round(rng.uniform(0.3, 1.0), 2), "ALA": round(rng.uniform(0.2, 0.5), 2),
          "ASN": round(rng.uniform(3, 5), 2), "MAb": 0.0, "V": round(rng.uniform(1.8, 2.2), 3)}
    bolus_share = round(rng.uniform(0.025, 0.045), 4)
    threshold = round(rng.uniform(2.0, 3.0) if lean else rng.uniform(2.0, 10.0), 1)
    target = round(rng.uniform(max(threshold + 6.0, 10.0), 25.0), 1)
    first_feed_day = int(rng.integers(2, 4))
    # Off-line samples: every 6-12 h, the last at harvest.
    t_end = on_clock(24.0 * days + rng.uniform(8.0, 10.0), CLOCK)
    samples, nominal = [0.0], rng.uniform(6.0, 12.0)
    while nominal < t_end - 6.0:
        samples.append(on_clock(nominal + rng.uniform(-1.5, 1.5), CLOCK))
        nominal += rng.uniform(6.0, 12.0)
    samples.append(t_end)
    skipped = {t for t in samples[1:-1] if rng.random() < 0.05}
    samples = [t for t in samples if t not in skipped]
    bolus_hours = [on_clock(24.0 * d + rng.uniform(8.0, 12.0), FEED_CLOCK)
                   for d in range(first_feed_day, days + 1)]
    bolus_hours = [t for t in bolus_hours if t + 0.5 < t_end]
    # Simulate sample to sample; the boluses are fixed in advance, the shots decided at
    # each sample from the assayed glucose.
    prog = Programme()
    y = np.array([y0[s] for s in STATES], float)
    shots = []
    t_prev = 0.0
    for ts in samples[1:]:
        # the boluses whose volume follows the culture: set when the pump starts
        for tb in bolus_hours:
            if t_prev <= tb < ts and tb not in prog.changes:
                vol = run_truth(model, y, prog.experiment(), [t_prev, tb])[-1][STATES.index("V")] if tb > t_prev else y[-1]
                prog.set(tb, 0, round(bolus_share * vol / 0.5, 5))
                prog.set(tb + 0.5, 0, 0.0)
        y = run_truth(model, y, prog.experiment(), [t_prev, ts])[-1]
        t_prev = ts
        glc_read = noisy(y[STATES.index("GLC")], *OFFLINE["GLC"], rng)
        if ts < t_end and glc_read < threshold:
            mmol = (target - glc_read) * y[STATES.index("V")]
            rate = round(mmol / model.consts["GLC_G"] / 0.25, 6)
            t_shot = on_clock(ts + 0.25, FEED_CLOCK)
            prog.set(t_shot, 1, rate)
            prog.set(t_shot + 0.25, 1, 0.0)
            shots.append({"t": t_shot, "glucose_read": round(glc_read, 3), "mmol": round(mmol, 3),
                          "F_G": rate})
    return {"name": name, "days": days, "t_end": t_end, "y0": y0, "bolus_share": bolus_share,
            "threshold": threshold, "target": target, "first_feed_day": first_feed_day,
            "samples": samples, "skipped": sorted(skipped), "shots": shots, "programme": prog}


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--batches", type=int, default=9)
    ap.add_argument("--seed", type=int, default=909)
    ap.add_argument("--out", default=str(CASE / "data/campaign.csv"))
    ap.add_argument("--truth", default=str(CASE / "data/campaign_truth.json"))
    ap.add_argument("--clean", default=str(CASE / "data/campaign_clean.csv"))
    args = ap.parse_args()

    rng = np.random.default_rng(args.seed)
    model = gbmlib.Model(CASE / "truth.gbm")
    assert model.states == STATES and model.inputs == INPUTS, (model.states, model.inputs)
    rows, clean, batches = [], [], []
    for b in range(args.batches):
        spec = batch(model, f"C{b + 1}", rng, lean=(b == args.batches - 1))
        t_end, prog = spec["t_end"], spec["programme"]
        online = [on_clock(3.0 * k + rng.uniform(-0.1, 0.1), CLOCK) for k in range(1, int(t_end / 3.0))]
        online = [t for t in online if 0 < t < t_end]
        times = sorted(set([0.0] + list(prog.changes) + online + spec["samples"]))
        exp = prog.experiment()
        y0 = [spec["y0"][s] for s in STATES]
        truth = run_truth(model, y0, exp, times)
        online_set, sample_set = set(online), set(spec["samples"])
        with_aa = {t: (t == 0.0 or rng.random() < 0.6) for t in spec["samples"]}
        for t, y in zip(times, truth):
            change = prog.changes.get(t, [None, None])
            row = {"experiment": spec["name"], "t": t,
                   "F": math.nan if change[0] is None else change[0],
                   "F_G": math.nan if change[1] is None else change[1]}
            cells = {s: math.nan for s in STATES}
            value = dict(zip(STATES, y))
            if t in online_set:
                for s in ("Xv", "V"):
                    cells[s] = noisy(value[s], *ONLINE[s], rng)
            if t in sample_set:
                for s, (r, a) in OFFLINE.items():
                    if s in ("ALA", "ASN") and not with_aa[t]:
                        continue
                    if s == "MAb" and 0.0 < t < 48.0:
                        continue
                    if t > 0.0 and rng.random() < 0.04:
                        continue
                    cells[s] = noisy(value[s], r, a, rng)
                if t == 0.0:
                    cells["V"] = noisy(value["V"], *ONLINE["V"], rng)
            if all(math.isnan(v) for v in cells.values()) and math.isnan(row["F"]) and math.isnan(row["F_G"]):
                continue
            row.update(cells)
            rows.append(row)
            held = exp["inputs"][max(int(np.searchsorted(exp["t"], t, side="right")) - 1, 0)]
            clean.append({"experiment": spec["name"], "t": t, "F": held[0], "F_G": held[1], **value})
        low = truth[:, STATES.index("GLC")] < 2.0
        lac = truth[:, STATES.index("LAC")]
        batches.append({
            "name": spec["name"], "days": spec["days"], "t_end": t_end, "initial_state": spec["y0"],
            "bolus_share": spec["bolus_share"], "glucose_threshold": spec["threshold"],
            "glucose_target": spec["target"], "first_feed_day": spec["first_feed_day"],
            "samples": spec["samples"], "skipped_samples": spec["skipped"], "shots": spec["shots"],
            "input_breaks": [float(t) for t in exp["t"]], "input_levels": exp["inputs"].tolist(),
            "rows": sum(1 for r in rows if r["experiment"] == spec["name"]),
            "hours_glucose_below_2mM": round(float(np.sum(np.diff(times)[low[1:]])), 2),
            "lactate_peak": {"t": float(times[int(np.argmax(lac))]), "LAC": float(lac.max())},
            "final_state": dict(zip(STATES, map(float, truth[-1]))),
        })
        xv = truth[:, 0]
        print(f"{spec['name']}: {spec['days']} d ({t_end} h), {len(spec['samples'])} samples, "
              f"{len(spec['shots'])} shots (threshold {spec['threshold']}, target {spec['target']}), "
              f"bolus {spec['bolus_share']}, peak Xv {xv.max():.1f} at {times[int(np.argmax(xv))]:.0f} h, "
              f"LAC peak {lac.max():.1f} at {times[int(np.argmax(lac))]:.0f} h end {lac[-1]:.1f}, "
              f"GLC < 2 mM for {batches[-1]['hours_glucose_below_2mM']} h, end MAb {truth[-1, 9]:.0f} "
              f"AMM {truth[-1, 6]:.1f} V {truth[-1, 10]:.2f}", file=sys.stderr)

    columns = INPUTS + STATES
    write_record(args.out, columns, UNITS, rows)
    write_clean(args.clean, columns, UNITS, clean)
    consts = model.consts
    write_json(args.truth, {
        "description": "truth of models/diagnose/campaign/data/campaign.csv, made by "
                       "bench/diagnose/campaign_generate.py from models/diagnose/campaign/truth.gbm",
        "command": f"python bench/diagnose/campaign_generate.py --batches {args.batches} --seed {args.seed}",
        "seed": args.seed,
        "integrator": {"method": "scipy Radau", "rtol": 1e-11, "atol": 1e-13},
        "truth_model": "models/diagnose/campaign/truth.gbm",
        "diagnosed_model": "models/diagnose/campaign/noshift.gbm",
        "consts": consts,
        "missing": ["lactate_uptake"],
        "true_effect_params": {
            "base": {k: consts[k] for k in ("mu_max", "k_d", "Y_XG", "Y_LG", "q_GLNmax", "Y_AG",
                                            "Y_XASN", "q_P")},
            "lactate_uptake": {k: consts[k] for k in ("q_Lmax", "K_iG")},
        },
        "noise": {"offline": OFFLINE, "online": ONLINE, "form": "value exp(rel N) + floor N, clipped at 0",
                  "missing_cells": 0.04, "skipped_samples": 0.05},
        "holdout": "C9",
        "batches": batches,
    })
    print(f"wrote {rel(args.out)} ({len(rows)} rows), {rel(args.clean)}, {rel(args.truth)}", file=sys.stderr)


if __name__ == "__main__":
    main()
