"""Shared pieces of the lab-like diagnosis records (bench/diagnose/*_generate.py): the
truth simulated by scipy Radau through bench/gbmlib.py (the truth .gbm file itself, via
gbc's IR), lab noise, times on an instrument clock, and the writers of the record (gbc's
format: one CSV, an `experiment` column, units in the headers, empty = not measured, an
input given at every change only), its noise-free twin and the truth JSON.

numpy + scipy + sympy; deterministic given the generators' seeds.
"""

import csv
import json
import math
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
sys.path.insert(0, str(ROOT / "bench"))
import gbmlib  # noqa: E402

GEN_METHOD, GEN_RTOL, GEN_ATOL = "Radau", 1e-11, 1e-13


def run_truth(model, y0, experiment, times, rtol=GEN_RTOL, atol=GEN_ATOL):
    """The truth's states at `times` (times[0] the start), the inputs held as in the
    record (`experiment`: {"t", "inputs"} of the input changes)."""
    return gbmlib.simulate(model, [], y0, experiment, times, method=GEN_METHOD, rtol=rtol, atol=atol)


def programme(breaks, levels):
    """An experiment dict (for gbmlib.input_segments) from input breaks and level rows."""
    return {"t": np.asarray(breaks, float), "inputs": np.asarray(levels, float).reshape(len(breaks), -1)}


def on_clock(t, clock):
    return round(round(t / clock) * clock, 6)


def noisy(value, rel, floor, rng):
    """Multiplicative log-normal noise `rel` plus an absolute floor, clipped at 0."""
    v = value * math.exp(rel * rng.standard_normal()) + floor * rng.standard_normal()
    return max(v, 0.0)


def fmt(v, digits=4):
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return ""
    return f"{v:.{digits}g}"


def write_record(path, columns, units, rows, digits=4, time_digits=2):
    """rows: dicts with "experiment", "t" and a value (or NaN/None) per column."""
    header = ["experiment", f"t [{units['t']}]"] + [f"{c} [{units[c]}]" for c in columns]
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="") as h:
        w = csv.writer(h, lineterminator="\n")
        w.writerow(header)
        for r in rows:
            w.writerow([r["experiment"], f"{r['t']:.{time_digits}f}"]
                       + [fmt(r.get(c, math.nan), digits) for c in columns])


def write_clean(path, columns, units, rows, time_digits=2):
    header = ["experiment", f"t [{units['t']}]"] + [f"{c} [{units[c]}]" for c in columns]
    with open(path, "w", newline="") as h:
        w = csv.writer(h, lineterminator="\n")
        w.writerow(header)
        for r in rows:
            w.writerow([r["experiment"], f"{r['t']:.{time_digits}f}"] + [repr(float(r[c])) for c in columns])


def write_json(path, doc):
    Path(path).write_text(json.dumps(doc, indent=1) + "\n")


def rel(path):
    path = Path(path).resolve()
    return str(path.relative_to(ROOT)) if path.is_relative_to(ROOT) else str(path)
