#!/usr/bin/env python3
"""The independent reference fits of the lab-like diagnosis cases (bench/diagnose/): scipy
least_squares (trf), multi-start, of the diagnosed model's params to the training part of
its record, without effects, with each candidate effect, and with the pairs a case names.

The objective is gbc diagnose's training gap, reproduced by bench/gbmlib.py (Problem):
- the split of src/diagnose/split.rs: with held-out experiments (`--holdout`) every row of
  the other experiments trains; with a tail split (`--val-fraction`, default 0.3 when
  nothing is held out) the rows before the last share of each experiment's measured rows;
- every training experiment is run free from its first row: a measured state takes its
  cell there, else its declared initial value (under the current params), else a value
  fitted with the params (Start::Fitted, first guess its first measured value); hidden
  states their declared values; inputs held from each row that gives them, the
  integrator restarted at every change;
- residuals (sim - data) / std_k / sqrt(cells) at every measured training cell, std_k the
  population standard deviation of state k over those cells (1 for a constant column):
  their sum of squares is the training gap (src/diagnose/fit.rs, Objective::residuals);
- params in gbc's transformed coordinates (positive: log; in [lo, hi]: logit).

The equations are the model's own, applied effects included: `gbc compile --emit ir
--effect NAME` parsed into SymPy (bench/gbmlib.py); integration by scipy LSODA (rtol 1e-8,
atol 1e-10, analytic Jacobian), the Jacobian of the residuals from forward sensitivities.
A run past --budget right-hand-side evaluations counts as failed (its residuals are 1e3,
so the step is rejected), as gbc's runs fail past 20000 steps per interval.

Starts: the declared values, then --starts - 1 perturbations theta0 + --spread * N(0, 1)
in transformed coordinates, drawn with --seed (the same draws for every fit of a case;
an effect's own params are perturbed too). Starts run in parallel on --jobs processes.

--pin [FIT:]NAME=VALUE (repeatable) holds a param at VALUE in the fits that have it (only
in FIT, base / an effect / a pair a+b, when given), fitting the rest: the optimum under the
pins gbc diagnose reports (base_fit.pinned, effects[].fit.pinned), to tell the cost of a pin
from a fit that stopped short.

Writes bench/diagnose/<case>_fit.json (--json): per fit the best training gap, its params,
the gap at the declared and (where the fit contains the truth) at the true values, every
start's gap, and wall times. numpy + scipy + sympy, and a built gbc.
"""

import argparse
import json
import math
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
sys.path.insert(0, str(ROOT / "bench"))
import gbmlib  # noqa: E402

CASES = {
    "overflow": {
        "model": "models/diagnose/overflow/monod.gbm",
        "record": "models/diagnose/overflow/data/overflow.csv",
        "truth": "models/diagnose/overflow/data/overflow_truth.json",
        "holdout": ["B4"],
        "pairs": [["overflow", "acetate_uptake"]],
        "true_set": ["overflow", "acetate_uptake"],
    },
    "hidden_biomass": {
        "model": "models/diagnose/hidden_biomass/norepression.gbm",
        "record": "models/diagnose/hidden_biomass/data/hidden_biomass.csv",
        "truth": "models/diagnose/hidden_biomass/data/hidden_biomass_truth.json",
        "holdout": [],
        "pairs": [],
        "true_set": ["glucose_repression"],
        # With X hidden only these products are identified (the free direction scales X0
        # and Y_X up and every q_max down).
        "combos": {"X0*q_Gmax": ("X0", "q_Gmax"), "X0*q_Xymax": ("X0", "q_Xymax"),
                   "X0*q_Fmax": ("X0", "q_Fmax"), "Y_X/X0": ("Y_X", "/X0")},
    },
    "campaign": {
        "model": "models/diagnose/campaign/noshift.gbm",
        "record": "models/diagnose/campaign/data/campaign.csv",
        "truth": "models/diagnose/campaign/data/campaign_truth.json",
        "holdout": ["C9"],
        "pairs": [],
        "true_set": ["lactate_uptake"],
    },
}

_PROBLEMS = {}


def problem_for(case, effects, settings):
    """The Problem of `case` with `effects` applied (cached per process)."""
    key = (case, tuple(effects))
    if key not in _PROBLEMS:
        c = CASES[case]
        model = gbmlib.Model(ROOT / c["model"], effects)
        experiments = gbmlib.read_record(ROOT / c["record"], model)
        parts = gbmlib.training_parts(experiments, settings["holdout"], settings["val_fraction"])
        _PROBLEMS[key] = gbmlib.Problem(model, parts, settings["method"], settings["rtol"],
                                        settings["atol"], settings["budget"])
    return _PROBLEMS[key]


def pins_of(effects, pins):
    """{param: value} of the --pin entries that apply to the fit of `effects`."""
    label = "+".join(effects) or "base"
    out = {}
    for fit, name, value in pins:
        if fit is None or fit == label or (fit != "base" and sorted(fit.split("+")) == sorted(effects)):
            out[name] = value
    return out


def pinned(problem, pin, theta):
    """`theta` with the pinned params at their values, and the indices of the free unknowns."""
    theta = np.array(theta, float)
    held = []
    for i, (name, c) in enumerate(zip(problem.model.param_names, problem.constraints)):
        if name in pin:
            theta[i] = gbmlib.to_theta(c, pin[name])
            held.append(i)
    return theta, np.array([i for i in range(len(theta)) if i not in held], int)


def run_start(args):
    case, effects, settings, index, theta = args
    problem = problem_for(case, effects, settings)
    problem.nfev = problem.njev = problem.rhs_evals = problem.failures = 0
    theta, free = pinned(problem, pins_of(effects, settings.get("pin") or []), theta)

    def full(x):
        out = theta.copy()
        out[free] = x
        return out

    t0 = time.perf_counter()
    gap_start = problem.gap(theta)
    sol = least_squares(lambda x: problem.residuals(full(x)), theta[free],
                        jac=lambda x: problem.jacobian(full(x))[:, free], method="trf",
                        ftol=settings["tol"], xtol=settings["tol"], gtol=settings["tol"],
                        max_nfev=settings["max_nfev"])
    wall = time.perf_counter() - t0
    x = full(sol.x)
    return {
        "start": index, "gap_start": gap_start, "gap": float(sol.fun @ sol.fun),
        "params": problem.named(x), "theta": [float(v) for v in x],
        "status": int(sol.status), "message": sol.message, "nfev": int(sol.nfev),
        "njev": int(sol.njev) if sol.njev is not None else None,
        "ode_rhs_evals": problem.rhs_evals, "failed_runs": problem.failures, "wall_s": wall,
        "cpu_s": time.process_time(),
    }


def combos(case, params):
    """The identified products of a case's params (CASES[case]["combos"])."""
    out = {}
    for name, (a, b) in CASES[case].get("combos", {}).items():
        if a in params and b.lstrip("/") in params:
            out[name] = params[a] / params[b[1:]] if b.startswith("/") else params[a] * params[b]
    return out


def true_values(problem, truth, effects):
    """The true values of the fit's params where the truth names them all, else None."""
    known = dict(truth.get("true_effect_params", {}).get("base", {}))
    for e in effects:
        known.update(truth.get("true_effect_params", {}).get(e, {}))
    names = problem.model.param_names
    if not all(n in known for n in names) or problem.fitted:
        return None
    return [known[n] for n in names]


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--case", required=True, choices=sorted(CASES))
    ap.add_argument("--fits", default="all",
                    help="comma-separated: base, an effect name, or a pair a+b (default: all)")
    ap.add_argument("--starts", type=int, default=12)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--spread", type=float, default=0.5, help="sd of the start perturbations")
    ap.add_argument("--holdout", nargs="*", default=None, help="default: the case's")
    ap.add_argument("--val-fraction", type=float, default=None)
    ap.add_argument("--method", default="LSODA", choices=["LSODA", "Radau", "BDF"])
    ap.add_argument("--rtol", type=float, default=1e-8)
    ap.add_argument("--atol", type=float, default=1e-10)
    ap.add_argument("--max-nfev", type=int, default=200)
    ap.add_argument("--budget", type=float, default=1e6)
    ap.add_argument("--tol", type=float, default=1e-10, help="ftol, xtol and gtol")
    ap.add_argument("--jobs", type=int, default=os.cpu_count())
    ap.add_argument("--pin", action="append", default=[], metavar="[FIT:]NAME=VALUE",
                    help="hold a param at VALUE (in FIT only, when given); repeatable")
    ap.add_argument("--json", default=None, help="default bench/diagnose/<case>_fit.json")
    args = ap.parse_args()
    pins = []
    for entry in args.pin:
        fit, _, rest = entry.rpartition(":")
        name, _, value = rest.partition("=")
        pins.append((fit or None, name, float(value)))

    case = CASES[args.case]
    holdout = case["holdout"] if args.holdout is None else args.holdout
    settings = {"holdout": holdout, "val_fraction": args.val_fraction, "method": args.method,
                "rtol": args.rtol, "atol": args.atol, "budget": args.budget, "tol": args.tol,
                "max_nfev": args.max_nfev, "pin": pins}
    truth = json.loads((ROOT / case["truth"]).read_text())
    declared = gbmlib.Model(ROOT / case["model"])
    effect_names = truth.get("effects") or []
    if not effect_names:
        import re
        effect_names = re.findall(r"^effect\s+(\w+)", (ROOT / case["model"]).read_text(), re.M)
    if args.fits == "all":
        fits = [[]] + [[e] for e in effect_names] + case["pairs"]
    else:
        fits = [[] if f == "base" else f.split("+") for f in args.fits.split(",")]

    print(f"case {args.case}: {declared.name}, holdout {holdout or 'none'}, "
          f"val fraction {args.val_fraction}, {len(fits)} fits x {args.starts} starts on {args.jobs} processes",
          file=sys.stderr)
    out_fits = []
    total = time.perf_counter()
    with ProcessPoolExecutor(max_workers=args.jobs) as pool:
        for effects in fits:
            problem = problem_for(args.case, effects, settings)
            pin = pins_of(effects, pins)
            theta0, _ = pinned(problem, pin, problem.theta0())
            rng = np.random.default_rng(args.seed)
            starts = [theta0] + [theta0 + args.spread * rng.standard_normal(len(theta0))
                                 for _ in range(args.starts - 1)]
            gap_declared = problem.gap(theta0)
            tv = true_values(problem, truth, effects)
            gap_truth = problem.gap(problem.theta0(tv)) if tv is not None else None
            t0 = time.perf_counter()
            results = list(pool.map(run_start, [(args.case, effects, settings, i, s.tolist())
                                                for i, s in enumerate(starts)]))
            wall = time.perf_counter() - t0
            best = min(results, key=lambda r: r["gap"])
            agree = sum(1 for r in results if r["gap"] <= best["gap"] * (1 + 1e-3) + 1e-15)
            label = "+".join(effects) or "base"
            out_fits.append({
                "fit": label, "effects": effects, "params": problem.model.param_names, "pinned": pin,
                "fitted_starts": [f"{problem.parts[p][0]['name']}.{problem.model.states[k]}"
                                  for p, k, _ in problem.fitted],
                "cells": problem.cells, "std": dict(zip(problem.model.states, problem.std.tolist())),
                "gap_declared": gap_declared, "gap_truth": gap_truth,
                "best": {"gap": best["gap"], "params": best["params"], "start": best["start"],
                         "identified_products": combos(args.case, best["params"])},
                "starts_reaching_best": agree, "wall_s": wall,
                "starts": [{k: v for k, v in r.items() if k != "theta"} for r in results],
            })
            print(f"{label:32s} best gap {best['gap']:.6g} (start {best['start']}, {agree}/{len(results)} "
                  f"within 0.1 %), declared {gap_declared:.4g}"
                  + (f", truth {gap_truth:.6g}" if gap_truth is not None else "")
                  + f", {wall:.1f} s; " + " ".join(f"{k} {v:.4g}" for k, v in best["params"].items())
                  + "".join(f"; {k} {v:.4g}" for k, v in combos(args.case, best["params"]).items()),
                  file=sys.stderr, flush=True)
    doc = {
        "what": f"scipy least_squares (trf) reference fits of {case['model']} to {case['record']} "
                "on gbc diagnose's training gap (sum of squared residuals = mean squared z-score "
                "over the measured training cells)",
        "case": args.case,
        "settings": {k: v for k, v in vars(args).items() if k not in ("json",)},
        "holdout": holdout, "val_fraction": args.val_fraction,
        "wall_s": time.perf_counter() - total,
        "fits": out_fits,
        "versions": {"python": sys.version.split()[0], "numpy": np.__version__,
                     "scipy": __import__("scipy").__version__, "sympy": __import__("sympy").__version__},
    }
    path = Path(args.json) if args.json else HERE / f"{args.case}_fit.json"
    path.write_text(json.dumps(doc, indent=1) + "\n")
    print(f"wrote {path}, {doc['wall_s']:.1f} s in all", file=sys.stderr)


if __name__ == "__main__":
    main()
