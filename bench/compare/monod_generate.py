#!/usr/bin/env python3
"""The "mechanism right" record of `gbc compare` (docs/compare.md): sparse E. coli
fed-batches simulated from the Monod model models/diagnose/overflow/monod.gbm itself (no
missing mechanism: plain Monod growth, acetate only diluted) by scipy Radau (rtol 1e-11,
atol 1e-13), restarted at every feed change.

Writes (defaults):
  models/compare/data/monod_batches.csv         the record gbc reads
  models/compare/data/monod_batches_truth.json  true params, starts, feed programmes, noise
  models/compare/data/monod_batches_clean.csv   the noise-free truth at every record row

True params q_Smax 1.1 1/h, K_S 0.05 g/L, Y_XS 0.5 g/g (the overflow record's base values).
Each batch (30-40 h): inoculation at t = 0 (X0 0.10-0.25 g/L, S0 6-10 g/L, A0 0.2-0.6 g/L
of acetate carried over with the inoculum, V0 1.6-2.2 L), a batch phase with F = 0 until the
glucose is spent (S < 0.1 g/L), then an exponential feed from within the next hour, on the
quarter hour: every 0.5-1 h the pump is set to mu_set X V / (0.5 S_F) from a 5 % reading of
X, mu_set 0.25-0.45 1/h (below mu_max = 0.55 1/h), capped by the pump (0.03-0.045 L/h). On
the feed the glucose sits at a few hundredths of a g/L while the biomass grows to tens of
g/L: the glucose balance's eigenvalue reaches some -100 to -1000 1/h, stiff against assays
hours apart.

Records: a row at t = 0 (F = 0; X, S, A, V), a row at every feed change (F only), and
off-line assays of X, S, A and V at about 10 irregular times per batch (jittered by up to
40 % of their spacing, on a 3-minute clock; the last at harvest), each cell missing with
probability 8 % (never at harvest). Noise: log-normal 4 % (V 1 %) plus an absolute floor
(X 0.02, S 0.005, A 0.005 g/L, V 0.002 L), clipped at 0, 4 significant digits.

numpy + scipy + sympy and a built gbc (target/release/gbc, for the model's IR);
deterministic by --seed.
"""

import argparse
import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "diagnose"))
from common import (ROOT, gbmlib, noisy, on_clock, programme, rel,  # noqa: E402
                    write_clean, write_json, write_record)

MODEL = ROOT / "models/diagnose/overflow/monod.gbm"
OUT = ROOT / "models/compare/data"
STATES = ["X", "S", "A", "V"]
UNITS = {"t": "h", "F": "L/h", "X": "g/L", "S": "g/L", "A": "g/L", "V": "L"}
TRUE = {"q_Smax": 1.1, "K_S": 0.05, "Y_XS": 0.5}
NOISE_REL = {"X": 0.04, "S": 0.04, "A": 0.04, "V": 0.01}
NOISE_ABS = {"X": 0.02, "S": 0.005, "A": 0.005, "V": 0.002}
MISSING = 0.08
CLOCK = 0.05  # h: sampling times recorded to 3 minutes
FEED_CLOCK = 0.25  # h: the pump is set on the quarter hour
Y_OPERATOR = 0.5  # g/g: the yield the operator's feed formula assumes
RTOL, ATOL = 1e-11, 1e-13


def run(model, p, y0, breaks, levels, times):
    return gbmlib.simulate(model, p, y0, programme(breaks, levels), times,
                           method="Radau", rtol=RTOL, atol=ATOL)


def feed_programme(model, p, y0, t_end, rng):
    """The batch phase and the operator's exponential feed, simulated piece by piece."""
    S_F = model.consts["S_F"]
    grid = np.arange(0.0, 20.0 + 1e-9, CLOCK)
    batch = run(model, p, y0, [0.0], [[0.0]], grid)
    t_spent = float(grid[np.argmax(batch[:, 1] < 0.1)])
    t_feed = math.ceil((t_spent + rng.uniform(0.0, 1.0)) / FEED_CLOCK) * FEED_CLOCK
    mu_set = round(rng.uniform(0.25, 0.45), 3)
    cap = round(rng.uniform(0.030, 0.045), 4)
    breaks, levels = [0.0], [[0.0]]
    t, y = 0.0, np.array(y0, float)
    change = t_feed
    while change < t_end:
        y = run(model, p, y, breaks, levels, [t, change])[-1]
        t = change
        X, V = y[0] * math.exp(0.05 * rng.standard_normal()), y[3]
        breaks.append(t)
        levels.append([round(min(mu_set * X * V / (Y_OPERATOR * S_F), cap), 5)])
        change = t + FEED_CLOCK * int(rng.integers(2, 5))  # 0.5 to 1 h
    return t_spent, t_feed, mu_set, cap, breaks, levels


def assays(t_end, rng):
    n = int(rng.integers(9, 12))
    spacing = t_end / n
    times = [on_clock((k + 1) * spacing + rng.uniform(-0.4, 0.4) * spacing, CLOCK) for k in range(n - 1)]
    return sorted({t for t in times if 0.5 <= t < t_end - 0.5}) + [t_end]


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--batches", type=int, default=5)
    ap.add_argument("--seed", type=int, default=2511)
    ap.add_argument("--out", default=str(OUT / "monod_batches.csv"))
    ap.add_argument("--truth", default=str(OUT / "monod_batches_truth.json"))
    ap.add_argument("--clean", default=str(OUT / "monod_batches_clean.csv"))
    args = ap.parse_args()

    rng = np.random.default_rng(args.seed)
    model = gbmlib.Model(MODEL)
    assert model.states == STATES and model.inputs == ["F"], (model.states, model.inputs)
    p = [TRUE[name] for name in model.param_names]
    rows, clean, batches = [], [], []
    for b in range(args.batches):
        name = f"B{b + 1}"
        t_end = float(rng.integers(30, 41))
        y0 = [round(rng.uniform(0.10, 0.25), 3), round(rng.uniform(6.0, 10.0), 2),
              round(rng.uniform(0.2, 0.6), 3), round(rng.uniform(1.6, 2.2), 2)]
        t_spent, t_feed, mu_set, cap, breaks, levels = feed_programme(model, p, y0, t_end, rng)
        sampled = assays(t_end, rng)
        times = sorted(set([0.0] + breaks + sampled))
        truth = run(model, p, y0, breaks, levels, times)
        level_at = {t: lv[0] for t, lv in zip(breaks, levels)}
        sampled_set = set(sampled)
        for t, y in zip(times, truth):
            row = {"experiment": name, "t": t, "F": level_at.get(t, math.nan)}
            cells = {s: math.nan for s in STATES}
            if t == 0.0 or t in sampled_set:
                for k, s in enumerate(STATES):
                    if t == 0.0 or t == t_end or rng.random() >= MISSING:
                        cells[s] = noisy(y[k], NOISE_REL[s], NOISE_ABS[s], rng)
            if all(math.isnan(v) for v in cells.values()) and math.isnan(row["F"]):
                continue
            row.update(cells)
            rows.append(row)
            F_held = levels[max(i for i, bt in enumerate(breaks) if bt <= t)][0]
            clean.append({"experiment": name, "t": t, "F": F_held, **dict(zip(STATES, y))})
        batches.append({
            "name": name, "t_end": t_end, "initial_state": dict(zip(STATES, y0)),
            "glucose_spent_at": t_spent, "feed_start": t_feed, "mu_set": mu_set, "feed_cap": cap,
            "feed_breaks": breaks, "feed_levels": [lv[0] for lv in levels], "assays": sampled,
            "final_state": dict(zip(STATES, map(float, truth[-1]))),
        })
        print(f"{name}: {t_end:.0f} h, glucose spent {t_spent:.2f} h, feed from {t_feed} h, mu_set {mu_set}, "
              f"cap {cap}, {len(breaks) - 1} feed changes, {len(sampled)} assays, end X {truth[-1, 0]:.1f} "
              f"S {truth[-1, 1]:.3f} A {truth[-1, 2]:.3f} V {truth[-1, 3]:.2f}", file=sys.stderr)

    write_record(args.out, ["F"] + STATES, UNITS, rows)
    write_clean(args.clean, ["F"] + STATES, UNITS, clean)
    write_json(args.truth, {
        "description": "truth of models/compare/data/monod_batches.csv, made by "
                       "bench/compare/monod_generate.py from models/diagnose/overflow/monod.gbm",
        "command": f"python bench/compare/monod_generate.py --batches {args.batches} --seed {args.seed}",
        "seed": args.seed,
        "integrator": {"method": "scipy Radau", "rtol": RTOL, "atol": ATOL},
        "truth_model": "models/diagnose/overflow/monod.gbm",
        "true_params": TRUE,
        "consts": model.consts,
        "missing": [],
        "noise": {"relative_lognormal": NOISE_REL, "absolute_floor": NOISE_ABS, "clip": 0.0,
                  "missing_cells": MISSING},
        "holdout": f"B{args.batches}",
        "batches": batches,
    })
    print(f"wrote {rel(args.out)} ({len(rows)} rows), {rel(args.clean)}, {rel(args.truth)}", file=sys.stderr)


if __name__ == "__main__":
    main()
