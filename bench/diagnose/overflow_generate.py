#!/usr/bin/env python3
"""The "overflow" record: sparse, multi-batch E. coli fed-batches simulated from
models/diagnose/overflow/truth.gbm (overflow metabolism and glucose-repressed acetate
re-uptake) by scipy Radau (rtol 1e-11, atol 1e-13), restarted at every feed change.

Writes (defaults):
  models/diagnose/overflow/data/overflow.csv         the record gbc reads
  models/diagnose/overflow/data/overflow_truth.json  true consts, starts, feed programmes, noise
  models/diagnose/overflow/data/overflow_clean.csv   the noise-free truth at every record row

Each batch (30-40 h): inoculation at t = 0 (X0 0.10-0.25 g/L, S0 6-10 g/L, A0 0.01-0.06
g/L carried over with the inoculum, V0 1.6-2.2 L), a batch phase with F = 0 until the
glucose is spent (S < 0.1 g/L, the DO spike), then the operator starts an exponential
feed within 0-1 h, on the quarter hour: every 1-2 h the pump is set to
mu_set X V / (0.5 S_F), from the OD (5 % reading error), with a per-batch target mu_set
(0.22-0.48 1/h: some batches above the critical rate Y_XS q_Sc = 0.44 1/h, where the
glucose piles up and overflows), capped by the pump (0.035-0.055 L/h). With probability
0.7 a batch has one feed pulse (1.6-2.4 times the level for 2-4 h), a common probe of the
overflow limit.

Records: a row at t = 0 (F = 0; X, S, A, V); a row at every feed change (F only); on-line
OD (X) about every hour (jittered by up to 0.2 h, on a 3-minute clock; 4 % missing);
HPLC assays of S and A at about 10 irregular times per batch (the last at harvest; 8 % of
the assays missing, 5 % of the single cells), V read at 80 % of them. Noise: log-normal
4 % (V 1 %) plus an absolute floor (X 0.03, S 0.01, A 0.01 g/L, V 0.005 L), clipped at 0,
4 significant digits.

numpy + scipy + sympy and a built gbc (target/release/gbc, for the truth's IR);
deterministic by --seed.
"""

import argparse
import math
import sys

import numpy as np

from common import (ROOT, gbmlib, noisy, on_clock, programme, rel, run_truth,  # noqa: F401
                    write_clean, write_json, write_record)

CASE = ROOT / "models/diagnose/overflow"
STATES = ["X", "S", "A", "V"]
UNITS = {"t": "h", "F": "L/h", "X": "g/L", "S": "g/L", "A": "g/L", "V": "L"}
NOISE_REL = {"X": 0.04, "S": 0.04, "A": 0.04, "V": 0.01}
NOISE_ABS = {"X": 0.03, "S": 0.01, "A": 0.01, "V": 0.005}
CLOCK = 0.05  # h: sampling times recorded to 3 minutes
FEED_CLOCK = 0.25  # h: the pump is set on the quarter hour
Y_OPERATOR = 0.5  # g/g: the yield the operator's feed formula assumes


def batch_programme(model, y0, t_end, rng):
    """The batch phase and the operator's feed programme, simulated piece by piece."""
    S_F = model.consts["S_F"]
    grid = np.arange(0.0, 20.0 + 1e-9, CLOCK)
    batch = run_truth(model, y0, programme([0.0], [[0.0]]), grid)
    t_spent = float(grid[np.argmax(batch[:, 1] < 0.1)])
    t_feed = math.ceil((t_spent + rng.uniform(0.0, 1.0)) / FEED_CLOCK) * FEED_CLOCK
    mu_set = round(rng.uniform(0.30, 0.50), 3)
    cap = round(rng.uniform(0.025, 0.040), 4)
    breaks, levels = [0.0], [[0.0]]
    t, y = 0.0, np.array(y0, float)
    change = t_feed
    while change < t_end:
        y = run_truth(model, y, programme(breaks, levels), [t, change])[-1]
        t = change
        X, V = y[0] * math.exp(0.05 * rng.standard_normal()), y[3]
        level = min(mu_set * X * V / (Y_OPERATOR * S_F), cap)
        hold = FEED_CLOCK * int(rng.integers(4, 9))  # 1 to 2 h
        breaks.append(t)
        levels.append([round(level, 5)])
        change = t + hold
    return t_spent, t_feed, mu_set, cap, breaks, levels


def sampling(t_end, rng):
    od = []
    for k in range(1, int(t_end)):
        if rng.random() >= 0.04:
            od.append(on_clock(k + rng.uniform(-0.2, 0.2), CLOCK))
    n = int(rng.integers(9, 12))
    spacing = t_end / n
    hplc = [on_clock((k + 1) * spacing + rng.uniform(-0.4, 0.4) * spacing, CLOCK) for k in range(n - 1)]
    hplc = sorted({t for t in hplc if 0.5 <= t < t_end - 0.5}) + [t_end]
    od.append(t_end)
    return sorted(set(od)), hplc


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--batches", type=int, default=4)
    ap.add_argument("--seed", type=int, default=2311)
    ap.add_argument("--out", default=str(CASE / "data/overflow.csv"))
    ap.add_argument("--truth", default=str(CASE / "data/overflow_truth.json"))
    ap.add_argument("--clean", default=str(CASE / "data/overflow_clean.csv"))
    args = ap.parse_args()

    rng = np.random.default_rng(args.seed)
    model = gbmlib.Model(CASE / "truth.gbm")
    assert model.states == STATES and model.inputs == ["F"], (model.states, model.inputs)
    rows, clean, batches = [], [], []
    for b in range(args.batches):
        name = f"B{b + 1}"
        t_end = float(rng.integers(30, 41))
        y0 = [round(rng.uniform(0.10, 0.25), 3), round(rng.uniform(6.0, 10.0), 2),
              round(rng.uniform(0.01, 0.06), 3), round(rng.uniform(1.6, 2.2), 2)]
        t_spent, t_feed, mu_set, cap, breaks, levels = batch_programme(model, y0, t_end, rng)
        od, hplc = sampling(t_end, rng)
        times = sorted(set([0.0] + breaks + od + hplc))
        truth = run_truth(model, y0, programme(breaks, levels), times)
        level_at = {t: lv[0] for t, lv in zip(breaks, levels)}
        od_set, hplc_set = set(od), set(hplc)
        for t, y in zip(times, truth):
            row = {"experiment": name, "t": t, "F": level_at.get(t, math.nan)}
            cells = {s: math.nan for s in STATES}
            if t == 0.0:
                cells = {s: noisy(y[k], NOISE_REL[s], NOISE_ABS[s], rng) for k, s in enumerate(STATES)}
            else:
                if t in od_set:
                    cells["X"] = noisy(y[0], NOISE_REL["X"], NOISE_ABS["X"], rng)
                if t in hplc_set and (t == t_end or rng.random() >= 0.08):
                    for k, s in ((1, "S"), (2, "A")):
                        if t == t_end or rng.random() >= 0.05:
                            cells[s] = noisy(y[k], NOISE_REL[s], NOISE_ABS[s], rng)
                    if t == t_end or rng.random() < 0.8:
                        cells["V"] = noisy(y[3], NOISE_REL["V"], NOISE_ABS["V"], rng)
            if all(math.isnan(v) for v in cells.values()) and math.isnan(row["F"]):
                continue
            row.update(cells)
            rows.append(row)
            F_held = levels[max(i for i, bt in enumerate(breaks) if bt <= t)][0]
            clean.append({"experiment": name, "t": t, "F": F_held, **dict(zip(STATES, y))})
        a_peak = int(np.argmax(truth[:, 2]))
        batches.append({
            "name": name, "t_end": t_end, "initial_state": dict(zip(STATES, y0)),
            "glucose_spent_at": t_spent, "feed_start": t_feed, "mu_set": mu_set, "feed_cap": cap,
            "feed_breaks": breaks, "feed_levels": [lv[0] for lv in levels],
            "rows": sum(1 for r in rows if r["experiment"] == name),
            "acetate_peak": {"t": times[a_peak], "A": float(truth[a_peak, 2])},
            "final_state": dict(zip(STATES, map(float, truth[-1]))),
        })
        print(f"{name}: {t_end:.0f} h, glucose spent {t_spent:.2f} h, feed from {t_feed} h, mu_set {mu_set}, "
              f"cap {cap}, {len(breaks) - 1} feed changes, acetate peak "
              f"{truth[a_peak, 2]:.2f} g/L at {times[a_peak]} h, end X {truth[-1, 0]:.1f} S {truth[-1, 1]:.3f} "
              f"A {truth[-1, 2]:.2f} V {truth[-1, 3]:.2f}", file=sys.stderr)

    write_record(args.out, ["F"] + STATES, UNITS, rows)
    write_clean(args.clean, ["F"] + STATES, UNITS, clean)
    write_json(args.truth, {
        "description": "truth of models/diagnose/overflow/data/overflow.csv, made by "
                       "bench/diagnose/overflow_generate.py from models/diagnose/overflow/truth.gbm",
        "command": f"python bench/diagnose/overflow_generate.py --batches {args.batches} --seed {args.seed}",
        "seed": args.seed,
        "integrator": {"method": "scipy " + "Radau", "rtol": 1e-11, "atol": 1e-13},
        "truth_model": "models/diagnose/overflow/truth.gbm",
        "diagnosed_model": "models/diagnose/overflow/monod.gbm",
        "consts": model.consts,
        "missing": ["overflow", "acetate_uptake"],
        "missing_note": "the pair together is the cause: overflow alone makes acetate pile up, "
                        "acetate_uptake alone has no acetate to take up",
        "true_effect_params": {
            "base": {k: model.consts[k] for k in ("q_Smax", "K_S", "Y_XS")},
            "overflow": {k: model.consts[k] for k in ("q_Sc", "Y_AS")},
            "acetate_uptake": {k: model.consts[k] for k in ("q_Amax", "K_iS")},
        },
        "noise": {"relative_lognormal": NOISE_REL, "absolute_floor": NOISE_ABS, "clip": 0.0},
        "holdout": "B4",
        "batches": batches,
    })
    print(f"wrote {rel(args.out)} ({len(rows)} rows), {rel(args.clean)}, {rel(args.truth)}", file=sys.stderr)


if __name__ == "__main__":
    main()
