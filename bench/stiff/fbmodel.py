"""The stiff fed-batch of models/stiff/fedbatch.gbm in NumPy, shared by the scripts of
bench/stiff: its right-hand side, Jacobian and param derivatives, a segment-wise
integrator (restarted at every feed change, as gbc restarts at every input switch), the
declared values read from the .gbm file, and a reader of the record format gbc reads
(one CSV with an `experiment` column, empty cells = not measured, inputs held).

numpy + scipy only.
"""

import csv
import math
import re
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp

ROOT = Path(__file__).resolve().parents[2]
MODEL = ROOT / "models/stiff/fedbatch.gbm"
RECORD = ROOT / "models/stiff/data/fedbatch.csv"
TRUTH = ROOT / "models/stiff/data/fedbatch_truth.json"

STATES = ["X", "S", "P", "V"]
UNITS = {"t": "h", "F": "L/h", "X": "g/L", "S": "g/L", "P": "g/L", "V": "L"}
PARAMS = ["mu_max", "K_S", "Y_XS", "m_S", "q_P", "K_I"]
CONSTS = ["S_F", "Y_PS", "K_P", "K_H"]


# ---------------------------------------------------------------------------------------
# The model file


def declared(path=MODEL):
    """The declared values of the .gbm file: {"params": {...}, "consts": {...},
    "init": {...}} (plain numbers only, which is all fedbatch.gbm writes)."""
    text = Path(path).read_text()
    out = {"params": {}, "consts": {}, "init": {}}
    pattern = re.compile(
        r"^\s*(param|const|state)\s+(\w+)\s*(?:\[[^\]]*\])?\s*=\s*([-+0-9.eE]+)", re.M
    )
    for kind, name, value in pattern.findall(text):
        key = {"param": "params", "const": "consts", "state": "init"}[kind]
        out[key][name] = float(value)
    assert list(out["params"]) == PARAMS, out["params"]
    assert list(out["consts"]) == CONSTS, out["consts"]
    assert list(out["init"]) == STATES, out["init"]
    return out


# ---------------------------------------------------------------------------------------
# Right-hand side, Jacobian, param derivatives


class FedBatch:
    """sat = S/(K_S+S); q_S = (mu_max/Y_XS + m_S) sat; q_Pr = q_P S/(K_P + S + S^2/K_I);
    mu = Y_XS (q_S - m_S - q_Pr/Y_PS); D = F/V;
    der X = (mu - D) X; der S = D (S_F - S) - q_S X; der P = q_Pr X - K_H P - D P;
    der V = F."""

    def __init__(self, params, consts):
        self.p = [float(params[name]) for name in PARAMS]
        self.c = [float(consts[name]) for name in CONSTS]

    def rhs(self, t, y, F):
        mu_max, K_S, Y_XS, m_S, q_P, K_I = self.p
        S_F, Y_PS, K_P, K_H = self.c
        X, S, P, V = y
        sat = S / (K_S + S)
        q_s = (mu_max / Y_XS + m_S) * sat
        q_pr = q_P * S / (K_P + S + S * S / K_I)
        mu = Y_XS * (q_s - m_S - q_pr / Y_PS)
        D = F / V
        return np.array(
            [(mu - D) * X, D * (S_F - S) - q_s * X, q_pr * X - K_H * P - D * P, F]
        )

    def jac(self, t, y, F):
        mu_max, K_S, Y_XS, m_S, q_P, K_I = self.p
        S_F, Y_PS, K_P, K_H = self.c
        X, S, P, V = y
        sat = S / (K_S + S)
        dsat = K_S / (K_S + S) ** 2
        q_max = mu_max / Y_XS + m_S
        q_s = q_max * sat
        dq_s = q_max * dsat
        den = K_P + S + S * S / K_I
        q_pr = q_P * S / den
        dq_pr = q_P * (K_P - S * S / K_I) / den**2
        mu = Y_XS * (q_s - m_S - q_pr / Y_PS)
        dmu = Y_XS * (dq_s - dq_pr / Y_PS)
        D = F / V
        dD = -F / V**2
        return np.array(
            [
                [mu - D, dmu * X, 0.0, -dD * X],
                [-q_s, -D - dq_s * X, 0.0, dD * (S_F - S)],
                [q_pr, dq_pr * X, -K_H - D, -dD * P],
                [0.0, 0.0, 0.0, 0.0],
            ]
        )

    def dfdp(self, t, y, F):
        """d f / d p (4 x 6), p in PARAMS order (plain values, not logs)."""
        mu_max, K_S, Y_XS, m_S, q_P, K_I = self.p
        S_F, Y_PS, K_P, K_H = self.c
        X, S, P, V = y
        sat = S / (K_S + S)
        dsat_dK = -S / (K_S + S) ** 2
        q_max = mu_max / Y_XS + m_S
        den = K_P + S + S * S / K_I
        q_pr = q_P * S / den
        dqp_dq = S / den
        dqp_dKI = q_P * S**3 / (K_I**2 * den**2)
        out = np.zeros((4, 6))
        out[0, 0] = sat * X
        out[1, 0] = -sat / Y_XS * X
        out[0, 1] = Y_XS * q_max * dsat_dK * X
        out[1, 1] = -q_max * dsat_dK * X
        out[0, 2] = (m_S * sat - m_S - q_pr / Y_PS) * X
        out[1, 2] = mu_max / Y_XS**2 * sat * X
        out[0, 3] = Y_XS * (sat - 1.0) * X
        out[1, 3] = -sat * X
        out[0, 4] = -Y_XS * dqp_dq / Y_PS * X
        out[2, 4] = dqp_dq * X
        out[0, 5] = -Y_XS * dqp_dKI / Y_PS * X
        out[2, 5] = dqp_dKI * X
        return out


# ---------------------------------------------------------------------------------------
# Feed programmes and integration


def feed_at(breaks, levels, t):
    """The feed held at time t (levels[i] from breaks[i] on; before breaks[0], levels[0])."""
    i = max(int(np.searchsorted(breaks, t, side="right")) - 1, 0)
    return levels[i]


def segments(breaks, levels, t0, t1):
    """(start, end, F) pieces of [t0, t1] on which the feed is constant."""
    cuts = [b for b in breaks if t0 < b < t1]
    edges = [t0] + cuts + [t1]
    return [(a, b, feed_at(breaks, levels, a)) for a, b in zip(edges[:-1], edges[1:])]


class BudgetExceeded(RuntimeError):
    """A run took more right-hand-side evaluations than its budget (see Budget)."""


class Budget:
    """Counts right-hand-side evaluations across the runs it is passed to and raises
    BudgetExceeded past `limit` (None: no limit). The fit uses it as gbc diagnose uses its
    20000-step limit per interval: a run at wild params that would take far longer than
    usual is declared failed, so that the optimiser steps back."""

    def __init__(self, limit=None):
        self.limit, self.count = limit, 0

    def wrap(self, f):
        def counted(t, y):
            self.count += 1
            if self.limit is not None and self.count > self.limit:
                raise BudgetExceeded(f"more than {self.limit} right-hand-side evaluations")
            return f(t, y)

        return counted


def simulate(model, y0, breaks, levels, times, method="Radau", rtol=1e-10, atol=1e-14,
             use_jac=True, budget=None):
    """States at `times` (sorted, times[0] the start) from y0, restarting the integrator at
    every feed change. Returns (array len(times) x 4, number of rhs evaluations). `atol`
    may be a scalar or one value per state; `budget` an optional Budget."""
    budget = budget or Budget()
    times = np.asarray(times, dtype=float)
    out = np.empty((len(times), 4))
    out[0] = y0
    y = np.array(y0, dtype=float)
    nfev = 0
    for a, b, F in segments(breaks, levels, times[0], times[-1]):
        inside = times[(times > a) & (times <= b)]
        kwargs = {}
        if use_jac and method in ("Radau", "BDF", "LSODA"):
            kwargs["jac"] = lambda t, y, F=F: model.jac(t, y, F)
        sol = solve_ivp(
            budget.wrap(lambda t, y, F=F: model.rhs(t, y, F)),
            (a, b),
            y,
            method=method,
            t_eval=np.append(inside, b) if (len(inside) == 0 or inside[-1] != b) else inside,
            rtol=rtol,
            atol=atol,
            **kwargs,
        )
        if sol.status != 0:
            raise RuntimeError(f"integration failed on [{a}, {b}]: {sol.message}")
        nfev += sol.nfev
        idx = np.searchsorted(times, inside)
        out[idx] = sol.y[:, : len(inside)].T
        y = sol.y[:, -1]
    return out, nfev


def simulate_sens(model, y0, breaks, levels, times, method="Radau", rtol=1e-8, atol=1e-10,
                  budget=None):
    """States and their forward sensitivities to log(params) at `times`: returns
    (states len(times) x 4, sens len(times) x 4 x 6, rhs evaluations). The initial state
    does not depend on the params (cells or declared numbers). `budget`: see simulate."""
    budget = budget or Budget()
    npar = len(PARAMS)
    pvals = np.array(model.p)
    times = np.asarray(times, dtype=float)
    states = np.empty((len(times), 4))
    sens = np.zeros((len(times), 4, npar))
    states[0] = y0
    z = np.concatenate([np.asarray(y0, float), np.zeros(4 * npar)])
    nfev = 0

    def f(t, z, F):
        y = z[:4]
        s = z[4:].reshape(4, npar)
        ds = model.jac(t, y, F) @ s + model.dfdp(t, y, F) * pvals
        return np.concatenate([model.rhs(t, y, F), ds.ravel()])

    def jac(t, z, F):
        # Newton matrix: the states' Jacobian on every block (the second-derivative
        # coupling of the sensitivities to the states is left out; it only slows Newton).
        return _blockjac(model.jac(t, z[:4], F), npar)

    for a, b, F in segments(breaks, levels, times[0], times[-1]):
        inside = times[(times > a) & (times <= b)]
        t_eval = np.append(inside, b) if (len(inside) == 0 or inside[-1] != b) else inside
        sol = solve_ivp(
            budget.wrap(lambda t, z, F=F: f(t, z, F)),
            (a, b),
            z,
            method=method,
            t_eval=t_eval,
            rtol=rtol,
            atol=atol,
            jac=lambda t, z, F=F: jac(t, z, F),
        )
        if sol.status != 0:
            raise RuntimeError(f"integration failed on [{a}, {b}]: {sol.message}")
        nfev += sol.nfev
        idx = np.searchsorted(times, inside)
        states[idx] = sol.y[:4, : len(inside)].T
        sens[idx] = sol.y[4:, : len(inside)].T.reshape(len(inside), 4, npar)
        z = sol.y[:, -1]
    return states, sens, nfev


def _blockjac(J, npar):
    """Jacobian of (y, s) -> (f, J s + f_p) without the d(J s)/dy coupling: the state block
    J, and J on each sensitivity block's diagonal (sensitivities ordered state-major,
    s[i, k] at 4 + i * npar + k)."""
    n = 4 * (1 + npar)
    out = np.zeros((n, n))
    out[:4, :4] = J
    # d(ds[i,k])/d s[j,k] = J[i,j]
    for k in range(npar):
        rows = 4 + np.arange(4) * npar + k
        out[np.ix_(rows, rows)] = J
    return out


# ---------------------------------------------------------------------------------------
# Records


def _cell(text):
    text = text.strip()
    if text == "" or text.lower() in ("na", "n/a", "nan"):
        return math.nan
    return float(text)


def read_record(path=RECORD):
    """Experiments of the record, in order of first appearance: a list of dicts with
    name, t (array), F (held at every row), feed breaks and levels (rows with a value),
    and cells {state: array with NaN where not measured}."""
    with open(path, newline="") as handle:
        rows = list(csv.reader(handle))
    header = [re.sub(r"\s*\[.*\]\s*$", "", h).strip() for h in rows[0]]
    col = {name: header.index(name) for name in ["experiment", "t", "F"] + STATES}
    experiments = {}
    for row in rows[1:]:
        if not row:
            continue
        name = row[col["experiment"]]
        e = experiments.setdefault(name, {"name": name, "t": [], "F_cells": [], "cells": {s: [] for s in STATES}})
        e["t"].append(float(row[col["t"]]))
        e["F_cells"].append(_cell(row[col["F"]]))
        for s in STATES:
            e["cells"][s].append(_cell(row[col[s]]))
    out = []
    for e in experiments.values():
        t = np.array(e["t"])
        cells_F = np.array(e["F_cells"])
        if math.isnan(cells_F[0]):
            raise ValueError(f"experiment {e['name']}: no feed value at the first row")
        held = cells_F.copy()
        for i in range(1, len(held)):
            if math.isnan(held[i]):
                held[i] = held[i - 1]
        given = ~np.isnan(cells_F)
        out.append(
            {
                "name": e["name"],
                "t": t,
                "F": held,
                "breaks": t[given],
                "levels": cells_F[given],
                "cells": {s: np.array(v) for s, v in e["cells"].items()},
            }
        )
    return out


def start_state(experiment, init):
    """A free run's start (records spec, section 3): a state's cell at the first row, else
    its declared initial value."""
    y0 = []
    for s in STATES:
        cell = experiment["cells"][s][0]
        y0.append(init[s] if math.isnan(cell) else cell)
    return np.array(y0)


def feed_file_rows(breaks, levels, t_end, step=0.5):
    """A uniform, complete (t, F) table on the grid k*step from 0 to t_end, holding the
    programme: what `gbc simulate --input F=csv(FILE)` reads today (it needs a uniformly
    sampled, complete file; every break must lie on the grid)."""
    n = int(round(t_end / step))
    for b in breaks:
        assert abs(b / step - round(b / step)) < 1e-9, f"feed change at {b} off the {step} h grid"
    grid = np.arange(n + 1) * step
    return [(t, feed_at(breaks, levels, t + 1e-9)) for t in grid]
