#!/usr/bin/env python3
"""Lab-like records of the stiff fed-batch (models/stiff/fedbatch.gbm) simulated with the
TRUE params by scipy Radau (rtol 1e-12, atol 1e-14), several batches each with its own
start and feed programme.

Writes (defaults):
  models/stiff/data/fedbatch.csv         the record gbc reads (experiment column, empty = not measured)
  models/stiff/data/fedbatch_truth.json  true params, initial states, feed programmes, noise
  models/stiff/data/fedbatch_clean.csv   the noise-free truth at every record row

Each batch: inoculation at t = 0 (X0 0.2-0.5 g/L, S0 14-20 g/L, V0 4.5-5.5 L drawn per batch; P0 = 0), batch phase with
F = 0 until the sugar is spent (the DO spike; S < 0.05 g/L), then the operator starts the
feed within 0-1.5 h, on the half hour. The feed is changed every 2-8 h (half hours); each
level is a random fraction (35-75 %) of the culture's current sugar demand capacity
q_S,max X V / S_F, capped by a per-batch pump limit (0.006-0.010 L/h), so that the sugar stays limiting
(a few mg/L). Some batches have one pump stop of 0.5-1.5 h.

Records: a row at t = 0 (F = 0; X, S, V assayed; P sometimes not); a row at every feed
change (the on-line pump signal: F only); off-line assays every 4-8 h (nominal) at times
jittered by up to +-1 h, on a 0.05 h (3 min) clock, the last at harvest; an assay is
skipped with probability 0.06 and a single cell left empty with probability 0.05; V is
read at an assay with probability 0.7. Noise: multiplicative log-normal (3.5 % for X, S,
P; 1 % for V) plus an absolute floor (X 0.02, S 0.002, P 0.005 g/L, V 0.01 L), clipped
at 0, written with 4 significant digits.

numpy + scipy only; deterministic by --seed.
"""

import argparse
import csv
import json
import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import fbmodel as fm  # noqa: E402

TRUE_PARAMS = {
    "mu_max": 0.092,  # 1/h
    "K_S": 2.0e-3,  # g/L
    "Y_XS": 0.45,  # g/g
    "m_S": 0.014,  # 1/h
    "q_P": 0.005,  # 1/h
    "K_I": 0.10,  # g/L
}

NOISE_REL = {"X": 0.035, "S": 0.035, "P": 0.035, "V": 0.01}
NOISE_ABS = {"X": 0.02, "S": 0.002, "P": 0.005, "V": 0.01}
GEN_RTOL, GEN_ATOL = 1e-12, 1e-14
FEED_STEP = 0.5  # h: feed changes on the half hour
CLOCK = 0.05  # h: assay times recorded to 3 minutes


def q_s_max(p):
    """Largest specific sugar uptake of the true model (S >> K_S)."""
    return p["mu_max"] / p["Y_XS"] + p["m_S"]


def programme(model, p, y0, t_end, rng):
    """Builds one batch's feed programme by simulating it piece by piece."""
    # Batch phase: find when the sugar is spent.
    from scipy.integrate import solve_ivp

    spent = lambda t, y: y[1] - 0.05  # noqa: E731
    spent.terminal, spent.direction = True, -1
    sol = solve_ivp(lambda t, y: model.rhs(t, y, 0.0), (0, 100), y0, method="Radau",
                    rtol=1e-10, atol=1e-12, jac=lambda t, y: model.jac(t, y, 0.0),
                    events=spent)
    t_spent = float(sol.t_events[0][0])
    t_feed = math.ceil((t_spent + rng.uniform(0.0, 1.5)) / FEED_STEP) * FEED_STEP
    cap = round(rng.uniform(0.006, 0.010), 4)
    breaks, levels = [0.0], [0.0]
    t, y = 0.0, np.array(y0, float)
    stop = None
    if rng.random() < 0.35:  # one pump stop somewhere in the fed phase
        stop = (math.floor(rng.uniform(t_feed + 40, t_end - 30) / FEED_STEP) * FEED_STEP,
                float(rng.choice([0.5, 1.0, 1.5])))
    next_change = t_feed
    while next_change < t_end:
        y = fm.simulate(model, y, breaks, levels, [t, next_change], rtol=1e-10, atol=1e-13)[0][-1]
        t = next_change
        X, S, P, V = y
        if stop is not None and stop[0] <= t < stop[0] + stop[1]:
            level, hold = 0.0, stop[0] + stop[1] - t
        else:
            demand = q_s_max(p) * X * V / 500.0
            level = min(rng.uniform(0.35, 0.75) * demand, cap)
            level = max(round(level, 4), 0.0005)
            hold = FEED_STEP * rng.integers(4, 17)  # 2 to 8 h
            if stop is not None and t < stop[0] < t + hold:
                hold = stop[0] - t
        breaks.append(t)
        levels.append(level)
        next_change = t + hold
    return t_spent, t_feed, cap, stop, breaks, levels


def assay_times(t_end, rng):
    times = []
    nominal = rng.uniform(3.0, 6.0)
    while nominal < t_end - 2.0:
        times.append(round((nominal + rng.uniform(-1.0, 1.0)) / CLOCK) * CLOCK)
        nominal += rng.uniform(4.0, 8.0)
    times.append(t_end)
    times = sorted({round(t, 2) for t in times if 0.5 <= t <= t_end})
    return times


def noisy(value, state, rng):
    v = value * math.exp(NOISE_REL[state] * rng.standard_normal())
    v += NOISE_ABS[state] * rng.standard_normal()
    return max(v, 0.0)


def fmt(v):
    if isinstance(v, float) and math.isnan(v):
        return ""
    return f"{v:.4g}"


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--batches", type=int, default=9)
    ap.add_argument("--seed", type=int, default=20240)
    ap.add_argument("--out", default=str(fm.RECORD))
    ap.add_argument("--truth", default=str(fm.TRUTH))
    ap.add_argument("--clean", default=str(fm.RECORD.with_name("fedbatch_clean.csv")))
    args = ap.parse_args()

    rng = np.random.default_rng(args.seed)
    consts = fm.declared()["consts"]
    model = fm.FedBatch(TRUE_PARAMS, consts)
    rows, clean_rows, batches = [], [], []
    for b in range(args.batches):
        name = f"B{b + 1:02d}"
        t_end = float(rng.integers(210, 241))
        y0 = [round(rng.uniform(0.2, 0.5), 3), round(rng.uniform(14.0, 20.0), 2), 0.0,
              round(rng.uniform(4.5, 5.5), 2)]
        t_spent, t_feed, cap, stop, breaks, levels = programme(model, TRUE_PARAMS, y0, t_end, rng)
        assays = assay_times(t_end, rng)
        times = sorted(set([0.0] + [round(x, 2) for x in breaks] + assays))
        truth, _ = fm.simulate(model, y0, breaks, levels, times, rtol=GEN_RTOL, atol=GEN_ATOL)
        level_at = dict(zip([round(x, 2) for x in breaks], levels))
        assay_set = set(assays)
        p_at_start = rng.random() < 0.5
        for t, y in zip(times, truth):
            row = {"experiment": name, "t": t, "F": level_at.get(t, math.nan)}
            cells = {s: math.nan for s in fm.STATES}
            if t == 0.0:
                cells["X"] = noisy(y[0], "X", rng)
                cells["S"] = noisy(y[1], "S", rng)
                cells["V"] = noisy(y[3], "V", rng)
                if p_at_start:
                    cells["P"] = noisy(y[2], "P", rng)
            elif t in assay_set and (t == t_end or rng.random() >= 0.06):
                for k, s in enumerate(["X", "S", "P"]):
                    if rng.random() >= 0.05:
                        cells[s] = noisy(y[k], s, rng)
                if rng.random() < 0.7:
                    cells["V"] = noisy(y[3], "V", rng)
            if all(math.isnan(v) for v in cells.values()) and math.isnan(row["F"]):
                continue  # a skipped assay leaves no row
            row.update(cells)
            rows.append(row)
            clean_rows.append({"experiment": name, "t": t, "F": fm.feed_at(breaks, levels, t),
                               **dict(zip(fm.STATES, y))})
        batches.append({
            "name": name, "t_end": t_end, "initial_state": dict(zip(fm.STATES, y0)),
            "sugar_spent_at": t_spent, "feed_start": t_feed, "feed_cap": cap,
            "pump_stop": None if stop is None else {"start": stop[0], "hours": float(stop[1])},
            "feed_breaks": [float(x) for x in breaks], "feed_levels": [float(x) for x in levels],
            "rows": sum(1 for r in rows if r["experiment"] == name),
        })
        print(f"{name}: t_end {t_end:.0f} h, sugar spent {t_spent:.1f} h, feed from {t_feed} h, "
              f"{len(breaks) - 1} feed changes, cap {cap} L/h, stop {stop}, "
              f"X_end {truth[-1][0]:.1f} g/L, V_end {truth[-1][3]:.2f} L, P_end {truth[-1][2]:.2f} g/L",
              file=sys.stderr)

    header = ["experiment", "t [h]", "F [L/h]", "X [g/L]", "S [g/L]", "P [g/L]", "V [L]"]
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    with open(args.out, "w", newline="") as h:
        w = csv.writer(h, lineterminator="\n")
        w.writerow(header)
        for r in rows:
            w.writerow([r["experiment"], f"{r['t']:.2f}", fmt(r["F"])] + [fmt(r[s]) for s in fm.STATES])
    with open(args.clean, "w", newline="") as h:
        w = csv.writer(h, lineterminator="\n")
        w.writerow(header)
        for r in clean_rows:
            w.writerow([r["experiment"], f"{r['t']:.2f}", repr(float(r["F"]))] + [repr(float(r[s])) for s in fm.STATES])
    truth = {
        "description": "truth of models/stiff/data/fedbatch.csv, made by bench/stiff/generate.py",
        "command": f"python bench/stiff/generate.py --batches {args.batches} --seed {args.seed}",
        "seed": args.seed,
        "integrator": {"method": "scipy Radau", "rtol": GEN_RTOL, "atol": GEN_ATOL},
        "params": TRUE_PARAMS,
        "declared_params": fm.declared()["params"],
        "consts": consts,
        "noise": {"relative_lognormal": NOISE_REL, "absolute_floor": NOISE_ABS, "clip": 0.0},
        "batches": batches,
    }
    Path(args.truth).write_text(json.dumps(truth, indent=1) + "\n")
    print(f"wrote {args.out} ({len(rows)} rows), {args.clean}, {args.truth}", file=sys.stderr)


if __name__ == "__main__":
    main()
