#!/usr/bin/env python3
"""The independent reference fit of the stiff fed-batch: scipy least_squares (trf) of the
six params of models/stiff/fedbatch.gbm to models/stiff/data/fedbatch.csv.

The objective is gbc diagnose's training gap (src/diagnose/fit.rs, Objective::residuals;
src/diagnose/split.rs), reproduced exactly:
- every experiment is run free from its first row: a state takes its cell there, else its
  declared initial value (fedbatch.gbm declares all four); the feed is held from each row
  that gives it to the next (zero-order hold), the integrator restarted at every change;
- residuals (sim - data) / std_k at every measured cell of the training rows, std_k the
  population standard deviation of column k over those cells (all experiments pooled; 1
  for a constant column), all divided by sqrt(number of cells): the sum of squares is the
  mean squared z-score, the gap. scipy's `cost` is half of it; we report the sum.
- params in log coordinates (all are `positive`: p = exp(theta), as gbc transforms them).
Training rows: all rows (default), or with --val-fraction SHARE the rows before the last
SHARE of each experiment's measured rows (a row with at least one state cell), which is
gbc diagnose's default split at SHARE = 0.3 (the free run still starts at row 0).

Integration: scipy LSODA (default; --method Radau) at rtol 1e-8, atol 1e-10, analytic
Jacobian. Jacobian of the residuals: forward sensitivities to log(params) integrated with
the states (default), or --jacobian 2-point (scipy's finite differences, relative step
--diff-step). A run that takes more than --budget right-hand-side evaluations (default
1e6 per objective or Jacobian evaluation, about 40 times a usual one) counts as failed:
its residuals are all 1e3, so least_squares rejects the step and shrinks its trust region,
as gbc diagnose's runs fail past 20000 steps per interval. Without it, LSODA's method
switching can stall for minutes at the wild params a first step may try (K_S ~ 5e-6 g/L,
Y_XS ~ 0.04, K_I ~ 250 g/L). Starts: the declared values, then --starts - 1 log-normal perturbations
theta0 + --spread * N(0, 1) drawn with --seed.

Prints a summary and writes bench/stiff/fit_scipy.json (--json): best gap, params, the
gap at the declared and at the true params, per-start results, wall times and function /
Jacobian evaluations. numpy + scipy only.
"""

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
import fbmodel as fm  # noqa: E402

CONSTANT_COLUMN = 1e-12  # src/numeric/stats.rs
FAILED = 1e3  # residual value of every cell when a run fails (the step is then rejected)


def mean_std(values):
    """src/numeric/stats.rs mean_std: population deviation, 1 for a constant column."""
    values = np.asarray(values, float)
    if len(values) == 0:
        return 0.0, 1.0
    mean = float(values.mean())
    std = float(math.sqrt(((values - mean) ** 2).mean()))
    varies = std > CONSTANT_COLUMN * max(abs(mean), 1e-300) and math.isfinite(std)
    return mean, (std if varies else 1.0)


def train_end(experiment, share):
    """End (exclusive) of the training rows: split.rs `tail`."""
    n = len(experiment["t"])
    if share <= 0:
        return n
    measured = [i for i in range(n) if any(not math.isnan(experiment["cells"][s][i]) for s in fm.STATES)]
    # Rust's f64::round rounds half away from zero (Python's round is banker's).
    held = int(math.floor(len(measured) * share + 0.5))
    if held == 0 or held >= len(measured):
        raise SystemExit(f"experiment {experiment['name']}: share {share} leaves no training or no test rows")
    return measured[len(measured) - held]


class Problem:
    def __init__(self, experiments, share, method, rtol, atol, budget=None):
        decl = fm.declared()
        self.consts = decl["consts"]
        self.init = decl["init"]
        self.method, self.rtol, self.atol = method, rtol, atol
        self.budget = budget
        self.failed = 0
        self.parts = []  # (experiment, times up to train end, mask rows x states, data)
        pooled = {s: [] for s in fm.STATES}
        for e in experiments:
            end = train_end(e, share)
            cells = np.column_stack([e["cells"][s][:end] for s in fm.STATES])
            mask = ~np.isnan(cells)
            for k, s in enumerate(fm.STATES):
                pooled[s].extend(cells[mask[:, k], k])
            self.parts.append((e, e["t"][:end], mask, cells))
        self.std = np.array([mean_std(pooled[s])[1] for s in fm.STATES])
        self.cells = int(sum(m.sum() for _, _, m, _ in self.parts))
        self.scale = math.sqrt(max(self.cells, 1))
        self.nfev = 0
        self.njev = 0
        self.rhs_evals = 0

    def params(self, theta):
        return dict(zip(fm.PARAMS, np.exp(theta)))

    def _runs(self, theta, sens):
        budget = fm.Budget(self.budget)
        try:
            return self._run_all(theta, sens, budget)
        finally:
            self.rhs_evals += budget.count

    def _run_all(self, theta, sens, budget):
        model = fm.FedBatch(self.params(theta), self.consts)
        res, jac = [], []
        for e, times, mask, cells in self.parts:
            y0 = fm.start_state(e, self.init)
            if sens:
                states, s, _ = fm.simulate_sens(model, y0, e["breaks"], e["levels"], times,
                                                method=self.method, rtol=self.rtol, atol=self.atol,
                                                budget=budget)
            else:
                states, _ = fm.simulate(model, y0, e["breaks"], e["levels"], times,
                                        method=self.method, rtol=self.rtol, atol=self.atol,
                                        budget=budget)
            for k in range(4):
                rows = mask[:, k]
                res.append((states[rows, k] - cells[rows, k]) / self.std[k] / self.scale)
                if sens:
                    jac.append(s[rows, k, :] / self.std[k] / self.scale)
        r = np.concatenate(res)
        return r, (np.vstack(jac) if sens else None)

    def residuals(self, theta):
        self.nfev += 1
        try:
            r, _ = self._runs(theta, False)
        except (RuntimeError, FloatingPointError, ValueError):
            self.failed += 1
            return np.full(self.cells, FAILED)
        return r if np.all(np.isfinite(r)) else np.full(self.cells, FAILED)

    def jacobian(self, theta):
        self.njev += 1
        try:
            _, J = self._runs(theta, True)
        except (RuntimeError, FloatingPointError, ValueError):
            self.failed += 1
            return np.zeros((self.cells, len(theta)))
        return J if np.all(np.isfinite(J)) else np.zeros((self.cells, len(theta)))

    def gap(self, theta):
        r = self.residuals(theta)
        return float(r @ r)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--record", default=str(fm.RECORD))
    ap.add_argument("--starts", type=int, default=8)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--spread", type=float, default=0.5, help="sd of the log-normal start perturbations")
    ap.add_argument("--val-fraction", type=float, default=0.0,
                    help="hold out the last SHARE of each experiment's measured rows (0.3 = gbc diagnose's default)")
    ap.add_argument("--method", default="LSODA", choices=["LSODA", "Radau", "BDF"])
    ap.add_argument("--rtol", type=float, default=1e-8)
    ap.add_argument("--atol", type=float, default=1e-10)
    ap.add_argument("--jacobian", default="sens", choices=["sens", "2-point"])
    ap.add_argument("--diff-step", type=float, default=1e-6)
    ap.add_argument("--max-nfev", type=int, default=200)
    ap.add_argument("--budget", type=float, default=1e6,
                    help="right-hand-side evaluations per objective or Jacobian evaluation before "
                         "the run counts as failed (0: no limit)")
    ap.add_argument("--tol", type=float, default=1e-10, help="ftol, xtol and gtol of least_squares")
    ap.add_argument("--json", default=str(HERE / "fit_scipy.json"))
    args = ap.parse_args()

    experiments = fm.read_record(args.record)
    problem = Problem(experiments, args.val_fraction, args.method, args.rtol, args.atol,
                      int(args.budget) if args.budget > 0 else None)
    declared = fm.declared()["params"]
    theta0 = np.log([declared[p] for p in fm.PARAMS])
    truth = json.loads(fm.TRUTH.read_text())["params"] if fm.TRUTH.exists() else None
    rng = np.random.default_rng(args.seed)
    starts = [theta0] + [theta0 + args.spread * rng.standard_normal(len(theta0))
                         for _ in range(args.starts - 1)]
    print(f"{len(experiments)} experiments, {problem.cells} measured cells in the training rows, "
          f"std " + " ".join(f"{s} {v:.4g}" for s, v in zip(fm.STATES, problem.std)), file=sys.stderr)
    gap_declared = problem.gap(theta0)
    gap_truth = problem.gap(np.log([truth[p] for p in fm.PARAMS])) if truth else None
    print(f"gap at the declared params {gap_declared:.6g}"
          + (f", at the true params {gap_truth:.6g}" if truth else ""), file=sys.stderr)

    results = []
    total = time.perf_counter()
    for i, start in enumerate(starts):
        problem.nfev = problem.njev = problem.rhs_evals = problem.failed = 0
        t0 = time.perf_counter()
        sol = least_squares(
            problem.residuals, start,
            jac=problem.jacobian if args.jacobian == "sens" else "2-point",
            diff_step=args.diff_step if args.jacobian == "2-point" else None,
            method="trf", ftol=args.tol, xtol=args.tol, gtol=args.tol, max_nfev=args.max_nfev,
        )
        wall = time.perf_counter() - t0
        gap = float(sol.fun @ sol.fun)
        row = {
            "start": i, "start_params": problem.params(start), "gap_start": problem.gap(start),
            "gap": gap, "params": problem.params(sol.x), "status": int(sol.status),
            "message": sol.message, "nfev": int(sol.nfev),
            "njev": int(sol.njev) if sol.njev is not None else None,
            "residual_evals": problem.nfev, "jacobian_evals": problem.njev,
            "ode_rhs_evals": problem.rhs_evals, "failed_runs": problem.failed, "wall_s": wall,
        }
        results.append(row)
        print(f"start {i}: gap {row['gap_start']:.5g} -> {gap:.6g}, {sol.nfev} residuals, "
              f"{row['njev']} Jacobians, {problem.failed} failed, {wall:.1f} s, status {sol.status}; "
              + " ".join(f"{k} {v:.4g}" for k, v in row["params"].items()), file=sys.stderr, flush=True)
    total = time.perf_counter() - total
    best = min(results, key=lambda r: r["gap"])
    doc = {
        "what": "scipy least_squares (trf) reference fit of models/stiff/fedbatch.gbm to "
                "models/stiff/data/fedbatch.csv; gap = sum of squared residuals = mean squared "
                "z-score over the measured training cells (gbc diagnose's training gap)",
        "settings": {k: v for k, v in vars(args).items() if k != "json"},
        "cells": problem.cells, "std": dict(zip(fm.STATES, problem.std.tolist())),
        "gap_declared": gap_declared, "gap_truth": gap_truth, "truth": truth,
        "declared": declared,
        "best": {"gap": best["gap"], "params": best["params"], "start": best["start"]},
        "wall_s": total,
        "residual_evals": sum(r["residual_evals"] for r in results),
        "jacobian_evals": sum(r["jacobian_evals"] for r in results),
        "starts": results,
        "versions": {"python": sys.version.split()[0], "numpy": np.__version__,
                     "scipy": __import__("scipy").__version__},
    }
    Path(args.json).write_text(json.dumps(doc, indent=1) + "\n")
    print(f"best gap {best['gap']:.6g} (start {best['start']}), total {total:.1f} s, "
          f"{doc['residual_evals']} residual and {doc['jacobian_evals']} Jacobian evaluations")
    for p in fm.PARAMS:
        t = f"  truth {truth[p]:.4g}" if truth else ""
        print(f"  {p:7s} {best['params'][p]:.5g}   declared {declared[p]:.4g}{t}")


if __name__ == "__main__":
    main()
