"""The held-out error of the *true* model on monod_batches.csv, computed independently of
gbc with scipy: the floor a fitted mechanism or grey box can reach on that record.

The true model (models/diagnose/overflow/monod.gbm at the true params of
monod_batches_truth.json) runs free from the held-out batch's first row (its measured
values, as gbc's free runs start), its feed held between the rows that give it (scipy
Radau, rtol 1e-10); each measured cell after the first row is z-scored by the training
batches' population standard deviation of that state (docs/error-measure.md), and the
error is the mean over states of each state's mean squared z-score.

    python bench/compare/truth_error.py --holdout B5
"""
import argparse
import csv
import json
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT / "models/compare/data/monod_batches.csv"
TRUTH = ROOT / "models/compare/data/monod_batches_truth.json"
STATES = ["X", "S", "A", "V"]


def read(path):
    rows = {}
    with open(path) as f:
        reader = csv.reader(f)
        header = [h.split(" [")[0] for h in next(reader)]
        for row in reader:
            rec = dict(zip(header, row))
            rows.setdefault(rec["experiment"], []).append(
                {k: (float(v) if v != "" else None) for k, v in rec.items() if k != "experiment"})
    return rows


def rhs(p, feed):
    def f(t, y):
        x, s, a, v = y
        q_s = p["q_Smax"] * s / (p["K_S"] + s)
        d = feed(t) / v
        return [(p["Y_XS"] * q_s - d) * x, d * (p["S_F"] - s) - q_s * x, -d * a, feed(t)]
    return f


def held_feed(rows):
    knots = [(r["t"], r["F"]) for r in rows if r["F"] is not None]
    def feed(t):
        value = knots[0][1]
        for time, f in knots:
            if time <= t + 1e-12:
                value = f
        return value
    return feed


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--holdout", default="B5")
    args = ap.parse_args()
    truth = json.loads(TRUTH.read_text())
    params = dict(truth["true_params"], **truth["consts"])
    data = read(DATA)
    train = [rows for name, rows in data.items() if name != args.holdout]
    std = {s: np.std([r[s] for rows in train for r in rows if r[s] is not None]) for s in STATES}
    held = data[args.holdout]
    y0 = [held[0][s] for s in STATES]
    feed = held_feed(held)
    times = [r["t"] for r in held]
    # Integrate piece by piece between rows so the held feed's steps are hit exactly.
    y, states = np.array(y0), [np.array(y0)]
    for t0, t1 in zip(times[:-1], times[1:]):
        sol = solve_ivp(rhs(params, lambda t, f=feed(t0): f), (t0, t1), y, method="Radau",
                        rtol=1e-10, atol=1e-12)
        y = sol.y[:, -1]
        states.append(y)
    nmse = {}
    for i, s in enumerate(STATES):
        z = [((states[k][i] - r[s]) / std[s]) ** 2 for k, r in enumerate(held) if k > 0 and r[s] is not None]
        nmse[s] = float(np.mean(z))
    print(json.dumps({"held_out": args.holdout, "per_state": nmse,
                      "error": float(np.mean(list(nmse.values())))}, indent=1))


if __name__ == "__main__":
    main()
