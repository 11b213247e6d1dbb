#!/usr/bin/env python3
"""The "hidden_biomass" record: one batch of a xylose-fermenting yeast in lignocellulosic
hydrolysate, simulated from models/diagnose/hidden_biomass/truth.gbm (glucose represses
the xylose uptake) by scipy Radau (rtol 1e-11, atol 1e-13). Biomass is hidden: not in the
record.

Writes (defaults):
  models/diagnose/hidden_biomass/data/hidden_biomass.csv         the record gbc reads
  models/diagnose/hidden_biomass/data/hidden_biomass_truth.json  true consts, start, noise
  models/diagnose/hidden_biomass/data/hidden_biomass_clean.csv   the noise-free truth at every row (X too)

The batch: --hours (default 90) long, from the truth's declared start (G 38, Xy 19, Fur
1.5, E 0.3 g/L; X 0.5 g/L). 34 HPLC assays at irregular times (t = 0, then 19 about every
1.3 h over the first 25 h, jittered, then 14 about every 4.6 h, the last at the end), on a
3-minute clock; each assay measures glucose G, xylose Xy, furfural Fur and ethanol E; 4 %
of the single cells are missing (never at t = 0). Noise: log-normal 4 % plus an absolute
floor (G, Xy, E 0.05 g/L; Fur 0.005 g/L), clipped at 0, 4 significant digits. The held-out
part is gbc diagnose's default tail: the last 30 % of the measured rows.

--replicates 1,2,3 also writes data/replicates/hidden_biomass_s<seed>.csv: the same batch
with other assay times and noise (the record of each seed alone), to measure how a
diagnosis's verdict moves with the noise.

numpy + scipy + sympy and a built gbc (target/release/gbc, for the truth's IR);
deterministic by --seed.
"""

import argparse
import math
import sys

import numpy as np

from common import ROOT, gbmlib, noisy, on_clock, programme, rel, run_truth, write_clean, write_json, write_record

CASE = ROOT / "models/diagnose/hidden_biomass"
STATES = ["G", "Xy", "Fur", "E"]
UNITS = {"t": "h", "G": "g/L", "Xy": "g/L", "Fur": "g/L", "E": "g/L", "X": "g/L"}
NOISE_REL = {"G": 0.04, "Xy": 0.04, "Fur": 0.04, "E": 0.04}
NOISE_ABS = {"G": 0.05, "Xy": 0.05, "Fur": 0.005, "E": 0.05}
CLOCK = 0.05


def assay_times(hours, rng):
    early = [on_clock((k + 1) * 1.3 + rng.uniform(-0.4, 0.4), CLOCK) for k in range(19)]
    late_step = (hours - 25.0) / 14
    late = [on_clock(25.0 + (k + 1) * late_step + rng.uniform(-0.3, 0.3) * late_step, CLOCK)
            for k in range(13)] + [hours]
    times = sorted(set([0.0] + early + late))
    assert len(times) == 34, len(times)
    return times


def record(model, y0, hours, seed):
    """The record's rows and their noise-free twins for one seed."""
    rng = np.random.default_rng(seed)
    times = assay_times(hours, rng)
    truth = run_truth(model, y0, programme([0.0], np.zeros((1, 0))), times)
    rows, clean = [], []
    for t, y in zip(times, truth):
        row = {"experiment": "H1", "t": t}
        for k, s in enumerate(STATES):
            missing = t > 0 and rng.random() < 0.04
            row[s] = math.nan if missing else noisy(y[k], NOISE_REL[s], NOISE_ABS[s], rng)
        rows.append(row)
        clean.append({"experiment": "H1", "t": t, **dict(zip(STATES + ["X"], y))})
    return rows, clean


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--hours", type=float, default=90.0)
    ap.add_argument("--seed", type=int, default=4242)
    ap.add_argument("--out", default=str(CASE / "data/hidden_biomass.csv"))
    ap.add_argument("--truth", default=str(CASE / "data/hidden_biomass_truth.json"))
    ap.add_argument("--clean", default=str(CASE / "data/hidden_biomass_clean.csv"))
    ap.add_argument("--replicates", default="", help="comma-separated seeds of replicate records")
    args = ap.parse_args()

    model = gbmlib.Model(CASE / "truth.gbm")
    assert model.states == STATES and model.hidden == ["X"] and not model.inputs
    y0, _ = model.declared_start([])
    rows, clean = record(model, y0, args.hours, args.seed)
    write_record(args.out, STATES, UNITS, rows)
    for seed in [int(s) for s in args.replicates.split(",") if s]:
        path = CASE / f"data/replicates/hidden_biomass_s{seed}.csv"
        write_record(path, STATES, UNITS, record(model, y0, args.hours, seed)[0])
        print(f"wrote {rel(path)}", file=sys.stderr)
    write_clean(args.clean, STATES + ["X"], UNITS, clean)
    dense = gbmlib.simulate(model, [], y0, programme([0.0], np.zeros((1, 0))),
                            np.arange(0, args.hours + 1e-9, 0.05), method="Radau", rtol=1e-11, atol=1e-13)
    grid = np.arange(0, args.hours + 1e-9, 0.05)
    g_gone = float(grid[np.argmax(dense[:, 0] < 0.1)])
    f_gone = float(grid[np.argmax(dense[:, 2] < 0.01)])
    consts = model.consts
    write_json(args.truth, {
        "description": "truth of models/diagnose/hidden_biomass/data/hidden_biomass.csv, made by "
                       "bench/diagnose/hidden_biomass_generate.py from models/diagnose/hidden_biomass/truth.gbm",
        "command": f"python bench/diagnose/hidden_biomass_generate.py --hours {args.hours:g} --seed {args.seed}"
                   + (f" --replicates {args.replicates}" if args.replicates else ""),
        "seed": args.seed,
        "integrator": {"method": "scipy Radau", "rtol": 1e-11, "atol": 1e-13},
        "truth_model": "models/diagnose/hidden_biomass/truth.gbm",
        "diagnosed_model": "models/diagnose/hidden_biomass/norepression.gbm",
        "consts": consts,
        "initial_state": dict(zip(STATES + ["X"], map(float, y0))),
        "missing": ["glucose_repression"],
        "mimic": "furfural_xylose (furfural inhibits the xylose uptake): furfural is gone at "
                 f"{f_gone:.2f} h, glucose at {g_gone:.2f} h",
        "true_effect_params": {
            "base": {k: consts[k] for k in ("X0", "q_Gmax", "q_Xymax", "q_Fmax", "Y_X")},
            "glucose_repression": {"K_R": consts["K_R"]},
        },
        "free_direction": "with X hidden, X0 and Y_X scale up and every q_max down by the same "
                          "factor without changing G, Xy, Fur or E: only X0 q_max and Y_X / X0 are identified",
        "noise": {"relative_lognormal": NOISE_REL, "absolute_floor": NOISE_ABS, "clip": 0.0,
                  "missing_cells": 0.04},
        "glucose_gone_at": g_gone, "furfural_gone_at": f_gone,
        "final_state": dict(zip(STATES + ["X"], map(float, dense[-1]))),
        "replicate_seeds": [int(s) for s in args.replicates.split(",") if s],
        "rows": len(rows),
    })
    print(f"H1: {args.hours:g} h, {len(rows)} assays, glucose gone at {g_gone:.2f} h, furfural at "
          f"{f_gone:.2f} h, end " + " ".join(f"{s} {v:.3g}" for s, v in zip(STATES + ['X'], dense[-1])),
          file=sys.stderr)
    print(f"wrote {rel(args.out)}, {rel(args.clean)}, {rel(args.truth)}", file=sys.stderr)


if __name__ == "__main__":
    main()
