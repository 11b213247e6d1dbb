#!/usr/bin/env python3
"""What the lab data can say about the bioreactor yields, independently of gbc: the
integral form of the substrate balance,

    S(t) - S(0) - D int_0^t (S0 - S) = -sum_k theta_k [k(t) - k(0) + D int_0^t k],  k = X, A, B

(theta_k = 1 / Y_k; the production rates are eliminated through the X, A, B balances),
fitted by least squares over every assay of every experiment, with a free intercept per
experiment (its true S(0) is unknown). Cells are linearly interpolated between assays.

    python3 scripts/yield_bound.py models/bioreactor/data/lab/run{1,2,3,4}.csv

Needs numpy (an optional peer, `pip install numpy`). Used in docs/training.md.
"""
import csv, sys
import numpy as np

D, S0 = 0.05, 20.0


def load(path):
    rows = list(csv.DictReader(open(path)))
    time_header = [h for h in rows[0] if h.split(" ")[0] == "t"][0]
    t = np.array([float(r[time_header]) for r in rows])
    columns = {}
    for name in "XABS":
        header = [h for h in rows[0] if h.split(" ")[0] == name][0]
        v = np.array([float(r[header]) if r[header] else np.nan for r in rows])
        keep = ~np.isnan(v)
        columns[name] = np.interp(t, t[keep], v[keep])
    return t, columns


def main(paths):
    blocks = []
    for path in paths:
        t, c = load(path)
        cumulative = lambda v: np.concatenate([[0], np.cumsum(np.diff(t) * (v[1:] + v[:-1]) / 2)])
        y = c["S"] - c["S"][0] - D * cumulative(S0 - c["S"])
        x = np.stack([-(c[k] - c[k][0] + D * cumulative(c[k])) for k in "XAB"], 1)
        blocks.append((y, x))
    y = np.concatenate([b[0] for b in blocks])
    intercepts = np.zeros((len(y), len(blocks)))
    row = 0
    for index, (part, _) in enumerate(blocks):
        intercepts[row:row + len(part), index] = 1.0
        row += len(part)
    design = np.hstack([np.concatenate([b[1] for b in blocks]), intercepts])
    theta = np.linalg.lstsq(design, y, rcond=None)[0][:3]
    for name, value, truth in zip(["Y_X", "Y_A", "Y_B"], 1 / theta, [0.435, 0.607, 0.3]):
        print(f"{name} = {value:.4f} (truth {truth}, {100 * (value / truth - 1):+.1f} %)")


if __name__ == "__main__":
    main(sys.argv[1:])
