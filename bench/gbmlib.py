"""A closure-free `.gbm` model evaluated from Python, and gbc diagnose's training gap.

The equations come from gbc itself: `gbc compile MODEL --emit ir [--effect NAME]...` prints
the compiled model with every let inlined and the applied effects' params, hidden states
and patches merged in (consts as numbers). This module parses that text into SymPy, and
derives by SymPy the Jacobian in the states and the derivatives in the params, so that a
model (with any set of its effects applied) can be

- integrated by scipy (`simulate`: restarted at every input change, inputs held from each
  row that gives them, as gbc's free runs and `gbc simulate` do),
- integrated with its forward sensitivities to the params and to fitted starts
  (`simulate_sens`),
- fitted to a record exactly on gbc diagnose's training gap (`Problem`: the objective of
  `Objective::residuals` in src/diagnose/fit.rs over the training rows of
  src/diagnose/split.rs).

Records are read in gbc's format (records spec section 2): one CSV with an `experiment`
column (or one experiment per file), a time column `t`, units in brackets in the headers,
empty cells = not measured, inputs held from each given value.

Needs numpy, scipy and sympy, and a built gbc (default target/release/gbc).
"""

import csv
import math
import re
import subprocess
from pathlib import Path

import numpy as np
import sympy as sp
from scipy.integrate import solve_ivp

ROOT = Path(__file__).resolve().parents[1]
GBC = ROOT / "target/release/gbc"
CONSTANT_COLUMN = 1e-12  # src/numeric/stats.rs
FAILED = 1e3  # residual of every cell when a run fails (the step is then rejected)


# ---------------------------------------------------------------------------------------
# The functions of the language (docs/language.md, "Expressions")


class softplus(sp.Function):  # noqa: N801 (the language's spelling)
    """log(1 + exp(x))."""

    def fdiff(self, argindex=1):
        return sigmoid(self.args[0])


class sigmoid(sp.Function):  # noqa: N801
    """1 / (1 + exp(-x))."""

    def fdiff(self, argindex=1):
        s = sigmoid(self.args[0])
        return s * (1 - s)


def _softplus(x):
    return max(x, 0.0) + math.log1p(math.exp(-abs(x)))


def _sigmoid(x):
    if x >= 0:
        return 1.0 / (1.0 + math.exp(-x))
    e = math.exp(x)
    return e / (1.0 + e)


def _heaviside(x, h0=0.5):
    return 1.0 if x > 0 else (0.0 if x < 0 else h0)


def _sign(x):
    return 1.0 if x > 0 else (-1.0 if x < 0 else 0.0)


SCALAR = {
    "softplus": _softplus, "sigmoid": _sigmoid, "Heaviside": _heaviside, "sign": _sign,
    "Max": max, "Min": min, "Abs": abs, "exp": math.exp, "log": math.log,
    "sqrt": math.sqrt, "tanh": math.tanh, "pow": pow,
}
FUNCTIONS = {
    "exp": sp.exp, "log": sp.log, "sqrt": sp.sqrt, "abs": sp.Abs, "tanh": sp.tanh,
    "sigmoid": sigmoid, "softplus": softplus, "min": sp.Min, "max": sp.Max, "pow": sp.Pow,
}


# ---------------------------------------------------------------------------------------
# The compiled model


def compile_ir(path, effects=(), gbc=GBC):
    """The IR text of `gbc compile PATH --effect E...`."""
    command = [str(gbc), "compile", str(path), "--emit", "ir"]
    for effect in effects:
        command += ["--effect", effect]
    done = subprocess.run(command, capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"{' '.join(command)} failed:\n{done.stderr}")
    return done.stdout


_ITEM = re.compile(r"^\s+(?P<id>[a-z]+\d+)\s+(?P<name>\w+)(?:\s+\[(?P<unit>[^\]]*)\])?(?P<rest>.*)$")
_BOUNDS = re.compile(r"^(?P<expr>.*?)\s*\bin\s*\[(?P<lo>[^,\]]+),\s*(?P<hi>[^\]]+)\]\s*$")


def _split_constraint(text):
    """`= 0.5 positive` / `= 0.5 in [0.1, 1]` / `= 0.5` -> (expr text, constraint)."""
    text = text.strip()
    if text.startswith("="):
        text = text[1:].strip()
    if text.endswith(" positive") or text == "positive":
        return text[: -len("positive")].strip(), ("positive",)
    m = _BOUNDS.match(text)
    if m:
        return m["expr"].strip(), ("bounds", float(m["lo"]), float(m["hi"]))
    return text, ("free",)


class Model:
    """A closure-free model from its IR. Attributes: `name`, `inputs`, `states` (measured),
    `hidden`, `consts` {name: value}, `params` [(name, value, constraint)], `units`
    {name: unit}, `balances` {state: sympy expr} and `init` {state: sympy expr or None}.
    `variables` = states then hidden (the integration order)."""

    def __init__(self, path, effects=(), gbc=GBC, ir=None):
        self.path = Path(path)
        self.effects = tuple(effects)
        text = ir if ir is not None else compile_ir(path, effects, gbc)
        self.name = None
        self.inputs, self.states, self.hidden = [], [], []
        self.consts, self.params, self.units = {}, [], {}
        raw_init, raw_balance = {}, {}
        section = None
        for line in text.splitlines():
            if line.startswith("#") or not line.strip():
                continue
            if not line.startswith(" "):
                head = line.split()[0]
                if head == "model":
                    self.name = line.split()[1]
                if head in ("effect", "closure"):
                    section = None if head == "effect" else "closure"
                    if head == "effect":
                        break  # the effect blocks that follow are not applied
                    continue
                section = head
                continue
            if section == "balances":
                m = re.match(r"^\s+der\s+(\w+)\s*=\s*(.*)$", line)
                if not m:
                    raise ValueError(f"a balance I cannot read: {line!r} (only `der` models)")
                raw_balance[m[1]] = m[2]
                continue
            if section not in ("inputs", "states", "hidden", "consts", "params"):
                continue  # lets (inlined already), outputs
            m = _ITEM.match(line)
            if not m:
                raise ValueError(f"an IR line I cannot read: {line!r}")
            name, rest = m["name"], m["rest"]
            self.units[name] = m["unit"]
            if section == "inputs":
                self.inputs.append(name)
            elif section in ("states", "hidden"):
                (self.states if section == "states" else self.hidden).append(name)
                expr = rest.strip()[1:].strip() if rest.strip().startswith("=") else None
                raw_init[name] = expr or None
            elif section == "consts":
                self.consts[name] = float(rest.strip()[1:])
            elif section == "params":
                expr, constraint = _split_constraint(rest)
                self.params.append([name, expr, constraint])
        self.variables = self.states + self.hidden
        self.sym = {n: sp.Symbol(n) for n in self.variables + self.inputs + [p[0] for p in self.params]}
        consts = {n: sp.Float(v) for n, v in self.consts.items()}
        local = dict(FUNCTIONS)
        local.update(self.sym)
        local.update(consts)

        def parse(expr):
            return sp.sympify(expr.replace("^", "**"), locals=local)

        # Param guesses are constant expressions of numbers and consts.
        for p in self.params:
            p[1] = float(parse(p[1]))
        self.params = [tuple(p) for p in self.params]
        self.param_names = [p[0] for p in self.params]
        self.balances = {n: parse(raw_balance[n]) for n in self.variables}
        self.init = {n: (parse(raw_init[n]) if raw_init.get(n) else None) for n in self.variables}
        self._build()

    # -- derived functions -------------------------------------------------------------

    def _build(self):
        y = [self.sym[n] for n in self.variables]
        u = [self.sym[n] for n in self.inputs]
        p = [self.sym[n] for n in self.param_names]
        f = sp.Matrix([self.balances[n] for n in self.variables])
        J = f.jacobian(y) if y else sp.zeros(0, 0)
        Fp = f.jacobian(p) if p else sp.zeros(len(y), 0)
        self.n, self.np = len(y), len(p)
        mods = [SCALAR, "math"]
        self._f = sp.lambdify([y, u, p], list(f), modules=mods, cse=True)
        self._fjp = sp.lambdify([y, u, p], [list(f), list(J), list(Fp)], modules=mods, cse=True)
        self._J = sp.lambdify([y, u, p], list(J), modules=mods, cse=True)
        init_exprs, init_grads = [], []
        for n in self.variables:
            e = self.init[n] if self.init[n] is not None else sp.nan
            init_exprs.append(e)
            init_grads.append([sp.diff(e, q) if self.init[n] is not None else 0 for q in p])
        self._y0 = sp.lambdify([p], init_exprs, modules=mods)
        self._dy0 = sp.lambdify([p], init_grads, modules=mods)

    def rhs(self, y, u, p):
        return np.array(self._f(y, u, p), dtype=float)

    def jac(self, y, u, p):
        return np.array(self._J(y, u, p), dtype=float).reshape(self.n, self.n)

    def rhs_jac_dfdp(self, y, u, p):
        f, J, Fp = self._fjp(y, u, p)
        return (np.array(f, float), np.array(J, float).reshape(self.n, self.n),
                np.array(Fp, float).reshape(self.n, self.np))

    def declared_start(self, p):
        """Declared initial values (NaN where none), and their derivatives in the params."""
        return np.array(self._y0(p), float), np.array(self._dy0(p), float).reshape(self.n, self.np)

    def guesses(self):
        return np.array([v for _, v, _ in self.params], float)

    def constraints(self):
        return [c for _, _, c in self.params]


# ---------------------------------------------------------------------------------------
# Transforms (src/diagnose/fit.rs: positive = exp(theta), in [lo, hi] through a sigmoid)


def to_theta(constraint, value):
    if constraint[0] == "positive":
        return math.log(max(value, 5e-324))
    if constraint[0] == "bounds":
        lo, hi = constraint[1], constraint[2]
        q = min(max((value - lo) / (hi - lo), 1e-9), 1 - 1e-9)
        return math.log(q / (1 - q))
    return value


def from_theta(constraint, theta):
    if constraint[0] == "positive":
        return math.exp(theta)
    if constraint[0] == "bounds":
        return constraint[1] + (constraint[2] - constraint[1]) * _sigmoid(theta)
    return theta


def slope(constraint, theta):
    if constraint[0] == "positive":
        return math.exp(theta)
    if constraint[0] == "bounds":
        s = _sigmoid(theta)
        return (constraint[2] - constraint[1]) * s * (1 - s)
    return 1.0


# ---------------------------------------------------------------------------------------
# Records


def _cell(text):
    text = text.strip()
    if text == "" or text.lower() in ("na", "n/a", "nan"):
        return math.nan
    return float(text)


def read_record(paths, model, column_t="t"):
    """Experiments of a data set (records spec): a list of dicts with `name`, `t`, the
    inputs held at every row (`inputs`: rows x inputs), `breaks` (the rows' times where an
    input is given), and `cells` (rows x measured states, NaN = not measured). Experiments
    keep the order of their first appearance."""
    if isinstance(paths, (str, Path)):
        paths = [paths]
    experiments = {}
    for path in paths:
        with open(path, newline="") as handle:
            rows = list(csv.reader(handle))
        header = [re.sub(r"\s*\[.*\]\s*$", "", h).strip() for h in rows[0]]
        col = {h: i for i, h in enumerate(header)}
        for row in rows[1:]:
            if not row:
                continue
            name = row[col["experiment"]] if "experiment" in col else Path(path).stem
            e = experiments.setdefault(name, {"name": name, "t": [], "u": [], "cells": []})
            e["t"].append(float(row[col[column_t]]))
            e["u"].append([_cell(row[col[u]]) for u in model.inputs])
            e["cells"].append([_cell(row[col[s]]) if s in col else math.nan for s in model.states])
    out = []
    for e in experiments.values():
        t = np.array(e["t"])
        order = np.argsort(t, kind="stable")
        t = t[order]
        given = np.array(e["u"], float).reshape(len(t), len(model.inputs))[order]
        held = given.copy()
        for k in range(held.shape[1]):
            if math.isnan(held[0, k]):
                raise ValueError(f"experiment {e['name']}: no value of input {model.inputs[k]} at the first row")
            for i in range(1, len(held)):
                if math.isnan(held[i, k]):
                    held[i, k] = held[i - 1, k]
        out.append({"name": e["name"], "t": t, "inputs": held,
                    "cells": np.array(e["cells"], float).reshape(len(t), len(model.states))[order]})
    return out


def input_segments(experiment, t0, t1):
    """(start, end, inputs) pieces of [t0, t1] over which the held inputs are constant (a
    new piece at every row whose inputs differ from the previous row's, as gbc restarts
    only where a value changes)."""
    t, u = experiment["t"], experiment["inputs"]
    edges = [t0]
    for i in range(1, len(t)):
        if t0 < t[i] < t1 and not np.array_equal(u[i], u[i - 1]):
            edges.append(t[i])
    edges.append(t1)

    def held(at):
        i = max(int(np.searchsorted(t, at, side="right")) - 1, 0)
        return u[i]

    return [(a, b, held(a)) for a, b in zip(edges[:-1], edges[1:]) if b > a]


# ---------------------------------------------------------------------------------------
# Integration


class BudgetExceeded(RuntimeError):
    """A run took more right-hand-side evaluations than its budget."""


class Budget:
    """Counts right-hand-side evaluations and raises BudgetExceeded past `limit` (None: no
    limit): a run at wild params that would take far longer than usual is declared failed,
    as gbc diagnose's runs fail past 20000 steps per interval."""

    def __init__(self, limit=None):
        self.limit, self.count = limit, 0

    def tick(self):
        self.count += 1
        if self.limit is not None and self.count > self.limit:
            raise BudgetExceeded(f"more than {self.limit} right-hand-side evaluations")


def simulate(model, p, y0, experiment, times, method="LSODA", rtol=1e-8, atol=1e-10,
             budget=None):
    """States (all variables) at `times` (sorted, times[0] the start) from y0 under params
    `p`, the inputs of `experiment` held, restarted at every input change."""
    budget = budget or Budget()
    times = np.asarray(times, float)
    out = np.empty((len(times), model.n))
    out[0] = y0
    y = np.array(y0, float)
    p = list(map(float, p))
    for a, b, u in input_segments(experiment, times[0], times[-1]):
        u = list(map(float, u))
        inside = times[(times > a) & (times <= b)]
        t_eval = inside if len(inside) and inside[-1] == b else np.append(inside, b)

        def f(t, y, u=u):
            budget.tick()
            return model.rhs(y, u, p)

        sol = solve_ivp(f, (a, b), y, method=method, t_eval=t_eval, rtol=rtol, atol=atol,
                        jac=lambda t, y, u=u: model.jac(y, u, p))
        if sol.status != 0:
            raise RuntimeError(f"integration failed on [{a}, {b}]: {sol.message}")
        out[np.searchsorted(times, inside)] = sol.y[:, : len(inside)].T
        y = sol.y[:, -1]
    return out


def simulate_sens(model, p, dp, y0, s0, experiment, times, method="LSODA", rtol=1e-8,
                  atol=1e-10, budget=None):
    """States and forward sensitivities at `times`. `dp` (len np) scales each param's
    column (d p / d theta: the sensitivities are to the transformed coordinates); `s0`
    (n x m, m >= np) the sensitivities of the start: the first np columns to the thetas,
    the rest to fitted starts. Returns (states len x n, sens len x n x m)."""
    budget = budget or Budget()
    n, npar = model.n, model.np
    m = s0.shape[1]
    p = list(map(float, p))
    dp = np.asarray(dp, float)
    times = np.asarray(times, float)
    states = np.empty((len(times), n))
    sens = np.zeros((len(times), n, m))
    states[0], sens[0] = y0, s0
    z = np.concatenate([np.asarray(y0, float), np.asarray(s0, float).ravel()])

    def block(J):
        out = np.zeros((n * (1 + m), n * (1 + m)))
        out[:n, :n] = J
        for k in range(m):
            rows = n + np.arange(n) * m + k
            out[np.ix_(rows, rows)] = J
        return out

    for a, b, u in input_segments(experiment, times[0], times[-1]):
        u = list(map(float, u))
        inside = times[(times > a) & (times <= b)]
        t_eval = inside if len(inside) and inside[-1] == b else np.append(inside, b)

        def f(t, z, u=u):
            budget.tick()
            y = z[:n]
            fy, J, Fp = model.rhs_jac_dfdp(y, u, p)
            s = z[n:].reshape(n, m)
            ds = J @ s
            ds[:, :npar] += Fp * dp
            return np.concatenate([fy, ds.ravel()])

        sol = solve_ivp(f, (a, b), z, method=method, t_eval=t_eval, rtol=rtol, atol=atol,
                        jac=lambda t, z, u=u: block(model.jac(z[:n], u, p)))
        if sol.status != 0:
            raise RuntimeError(f"integration failed on [{a}, {b}]: {sol.message}")
        idx = np.searchsorted(times, inside)
        states[idx] = sol.y[:n, : len(inside)].T
        sens[idx] = sol.y[n:, : len(inside)].T.reshape(len(inside), n, m)
        z = sol.y[:, -1]
    return states, sens


# ---------------------------------------------------------------------------------------
# gbc diagnose's split and training gap


def mean_std(values):
    """src/numeric/stats.rs mean_std: population deviation, 1 for a constant column."""
    values = np.asarray(values, float)
    if len(values) == 0:
        return 0.0, 1.0
    mean = float(values.mean())
    std = float(math.sqrt(((values - mean) ** 2).mean()))
    varies = std > CONSTANT_COLUMN * max(abs(mean), 1e-300) and math.isfinite(std)
    return mean, (std if varies else 1.0)


def measured_rows(experiment):
    return [i for i in range(len(experiment["t"])) if np.any(~np.isnan(experiment["cells"][i]))]


def tail_split(experiment, share):
    """(train end, test start) of split.rs `tail`: the last `share` of the measured rows
    is scored, the rows before the first of them train."""
    rows = measured_rows(experiment)
    held = int(math.floor(len(rows) * share + 0.5))  # Rust rounds half away from zero
    if held == 0 or held >= len(rows):
        raise ValueError(f"experiment {experiment['name']}: share {share} leaves no training or no test rows")
    return rows[len(rows) - held]


def training_parts(experiments, holdout=(), share=None):
    """[(experiment, training row end)] as split.rs chooses them: with `holdout` names
    (and no share) whole experiments train and the named ones are only scored; else (share
    default 0.3) the rows before the tail of every experiment train."""
    if holdout and share is None:
        missing = set(holdout) - {e["name"] for e in experiments}
        if missing:
            raise ValueError(f"no experiment named {sorted(missing)}")
        return [(e, len(e["t"])) for e in experiments if e["name"] not in holdout]
    share = 0.3 if share is None else share
    return [(e, tail_split(e, share)) for e in experiments if e["name"] not in holdout]


class Problem:
    """gbc diagnose's training gap of `model` on the training parts: residuals
    (sim - data) / std_k / sqrt(cells) at every measured training cell, std_k the
    population deviation of state k over those cells; the unknowns are the params in
    transformed coordinates, then the fitted starts (states with no cell at their
    experiment's first row and no declared value: Start::Fitted, free coordinates, first
    guess the state's first measured value)."""

    def __init__(self, model, parts, method="LSODA", rtol=1e-8, atol=1e-10, budget=1e6):
        self.model = model
        self.method, self.rtol, self.atol = method, rtol, atol
        self.budget = int(budget) if budget else None
        self.parts = []
        pooled = [[] for _ in model.states]
        declared = [model.init[s] is not None for s in model.states]
        self.fitted = []  # (part index, state index, first guess)
        for e, end in parts:
            cells = e["cells"][:end]
            mask = ~np.isnan(cells)
            for k in range(len(model.states)):
                pooled[k].extend(cells[mask[:, k], k])
            starts = []
            for k in range(len(model.states)):
                if not math.isnan(e["cells"][0, k]):
                    starts.append(("cell", e["cells"][0, k]))
                elif declared[k]:
                    starts.append(("declared", None))
                else:
                    column = e["cells"][:, k]
                    first = column[~np.isnan(column)][0]
                    self.fitted.append((len(self.parts), k, float(first)))
                    starts.append(("fitted", len(self.fitted) - 1))
            self.parts.append((e, e["t"][:end], mask, cells, starts))
        self.std = np.array([mean_std(v)[1] for v in pooled])
        self.cells = int(sum(m.sum() for _, _, m, _, _ in self.parts))
        self.scale = math.sqrt(max(self.cells, 1))
        self.constraints = model.constraints()
        self.nfev = self.njev = self.rhs_evals = self.failures = 0

    # unknowns ---------------------------------------------------------------------------

    def theta0(self, values=None):
        values = self.model.guesses() if values is None else values
        return np.array([to_theta(c, v) for c, v in zip(self.constraints, values)]
                        + [g for _, _, g in self.fitted])

    def values(self, theta):
        """Params (constrained values) and fitted starts of the unknowns `theta`."""
        npar = self.model.np
        return (np.array([from_theta(c, t) for c, t in zip(self.constraints, theta[:npar])]),
                np.asarray(theta[npar:], float))

    def named(self, theta):
        p, starts = self.values(theta)
        out = dict(zip(self.model.param_names, map(float, p)))
        for (part, k, _), v in zip(self.fitted, starts):
            out[f"{self.parts[part][0]['name']}.{self.model.states[k]}(0)"] = float(v)
        return out

    def _start(self, part, p, starts):
        e, _, _, _, plan = self.parts[part]
        y0, dy0 = self.model.declared_start(p)
        m = self.model.np + len(self.fitted)
        s0 = np.zeros((self.model.n, m))
        for k, (kind, arg) in enumerate(plan):
            if kind == "cell":
                y0[k], dy0[k] = arg, 0.0
            elif kind == "fitted":
                y0[k], dy0[k] = starts[arg], 0.0
                s0[k, self.model.np + arg] = 1.0
        s0[:, : self.model.np] = dy0
        if np.any(np.isnan(y0)):
            raise ValueError(f"experiment {e['name']}: a hidden state without a declared start")
        return y0, s0

    # residuals --------------------------------------------------------------------------

    def _runs(self, theta, sens):
        budget = Budget(self.budget)
        p, starts = self.values(theta)
        dp = np.array([slope(c, t) for c, t in zip(self.constraints, theta[: self.model.np])])
        res, jac = [], []
        try:
            for i, (e, times, mask, cells, _) in enumerate(self.parts):
                y0, s0 = self._start(i, p, starts)
                s0[:, : self.model.np] *= dp
                if sens:
                    y, s = simulate_sens(self.model, p, dp, y0, s0, e, times, self.method,
                                         self.rtol, self.atol, budget)
                else:
                    y = simulate(self.model, p, y0, e, times, self.method, self.rtol,
                                 self.atol, budget)
                # residuals row by row, state by state (fit.rs record_residuals)
                rows, ks = np.nonzero(mask)
                res.append((y[rows, ks] - cells[rows, ks]) / self.std[ks] / self.scale)
                if sens:
                    jac.append(s[rows, ks, :] / (self.std[ks] * self.scale)[:, None])
        finally:
            self.rhs_evals += budget.count
        return np.concatenate(res), (np.vstack(jac) if sens else None)

    def residuals(self, theta):
        self.nfev += 1
        try:
            r, _ = self._runs(np.asarray(theta, float), False)
        except (RuntimeError, FloatingPointError, ValueError, OverflowError, ZeroDivisionError):
            self.failures += 1
            return np.full(self.cells, FAILED)
        return r if np.all(np.isfinite(r)) else np.full(self.cells, FAILED)

    def jacobian(self, theta):
        self.njev += 1
        try:
            _, J = self._runs(np.asarray(theta, float), True)
        except (RuntimeError, FloatingPointError, ValueError, OverflowError, ZeroDivisionError):
            self.failures += 1
            return np.zeros((self.cells, len(theta)))
        return J if np.all(np.isfinite(J)) else np.zeros((self.cells, len(theta)))

    def gap(self, theta):
        r = self.residuals(theta)
        return float(r @ r)
