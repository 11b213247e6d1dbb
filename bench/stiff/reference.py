#!/usr/bin/env python3
"""Independent scipy references for gbc's stiff integrator.

(a) Robertson (models/stiff/robertson.gbm): scipy Radau, rtol 1e-10, atol (1e-14, 1e-18,
    1e-18) for (y1, y2, y3), analytic Jacobian, at t = 0 and 4e-5, 4e-4, ..., 4e5 s;
    written to bench/stiff/robertson_reference.csv. Its own error is estimated by a
    second run at rtol 1e-12 (printed, and kept in reference_meta.json).
(b) The fed-batch (models/stiff/fedbatch.gbm) with the params DECLARED in the model file,
    every experiment of models/stiff/data/fedbatch.csv driven by its own feed programme,
    from its first row (a state's cell there, else its declared initial value, as gbc's
    free runs start), at every record time; Radau rtol 1e-10, atol 1e-14, analytic
    Jacobian, restarted at every feed change (as gbc restarts at input switches);
    written to bench/stiff/fedbatch_reference.csv, and the same with K_S = 2.7e-6 g/L
    (the other params declared) to bench/stiff/fedbatch_reference_ks2.7e-6.csv.
(c) Timing: scipy LSODA (rtol 1e-6, 1e-8) and Radau (rtol 1e-6; with the analytic and with
    a finite-difference Jacobian), atol 1e-12, wall time to integrate all batches at the
    record times (median of --repeats runs, default 5), at the declared K_S and at
    K_S = 2.7e-6 g/L; and Robertson to 4e5 s on the reference grid (LSODA rtol 1e-6, 1e-8,
    Radau rtol 1e-6, 1e-10; atol rtol * (1e-4, 1e-8, 1e-8)). Each config's max relative
    error against (a) or (b) is reported too. Written to bench/stiff/timing_scipy.json and
    printed as a table. (b) also reports how stiff the fed phase is: the largest
    |eigenvalue| of the Jacobian at the fed-phase rows (reference_meta.json).

It also writes what gbc needs to make the same runs: bench/stiff/feeds/<batch>.csv (each
batch's feed programme as a uniform, complete 0.5 h table: `gbc simulate --input
F=csv(FILE)` reads only such files today, and `steps(...)` draws random levels, so it
cannot replay a given programme) and bench/stiff/params_ks2.7e-6.json (for `--params`),
and prints the gbc commands (bench/stiff/compare.py runs them).

numpy + scipy only. --seed is accepted for uniformity; nothing here is random.
"""

import argparse
import csv
import json
import statistics
import sys
import time
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
import fbmodel as fm  # noqa: E402

ROBERTSON_TIMES = [0.0] + [4.0 * 10.0**k for k in range(-5, 6)]
ROBERTSON_K = (0.04, 3e7, 1e4)
ROBERTSON_ATOL = [1e-14, 1e-18, 1e-18]
SMALL_KS = 2.7e-6
GBC_DT = 0.05  # record times are on a 0.05 h clock
# Relative error floors (absolute, in the state's unit) of every comparison.
FLOORS = {"X": 1e-6, "S": 1e-8, "P": 1e-6, "V": 1e-6}
ROBERTSON_FLOORS = {"y1": 1e-12, "y2": 1e-16, "y3": 1e-12}


# ---------------------------------------------------------------------------------------
# Robertson


def robertson_rhs(t, y):
    k1, k2, k3 = ROBERTSON_K
    y1, y2, y3 = y
    return [-k1 * y1 + k3 * y2 * y3, k1 * y1 - k3 * y2 * y3 - k2 * y2 * y2, k2 * y2 * y2]


def robertson_jac(t, y):
    k1, k2, k3 = ROBERTSON_K
    y1, y2, y3 = y
    return [[-k1, k3 * y3, k3 * y2],
            [k1, -k3 * y3 - 2 * k2 * y2, -k3 * y2],
            [0.0, 2 * k2 * y2, 0.0]]


def robertson(rtol=1e-10, atol=ROBERTSON_ATOL, times=ROBERTSON_TIMES):
    sol = solve_ivp(robertson_rhs, (times[0], times[-1]), [1.0, 0.0, 0.0], method="Radau",
                    t_eval=times, rtol=rtol, atol=atol, jac=robertson_jac)
    assert sol.status == 0, sol.message
    return sol.y.T, sol


def robertson_commands(gbc="target/release/gbc", rtol=1e-10, atol=1e-16):
    """One gbc run per output time: the grid of `gbc simulate` is t_start + k dt (linear),
    so `--dt T --t-end T` gives the rows t = 0 and t = T."""
    return [
        (T, f"{gbc} simulate models/stiff/robertson.gbm --t-end {T:g} --dt {T:g} "
            f"--rtol {rtol:g} --atol {atol:g} -o robertson_{T:g}.csv")
        for T in ROBERTSON_TIMES[1:]
    ]


# ---------------------------------------------------------------------------------------
# Fed-batch


def params_with(ks=None):
    params = dict(fm.declared()["params"])
    if ks is not None:
        params["K_S"] = ks
    return params


def run_all(experiments, params, method="Radau", rtol=1e-10, atol=1e-14, use_jac=True):
    decl = fm.declared()
    model = fm.FedBatch(params, decl["consts"])
    out, nfev = [], 0
    for e in experiments:
        y0 = fm.start_state(e, decl["init"])
        states, n = fm.simulate(model, y0, e["breaks"], e["levels"], e["t"], method=method,
                                rtol=rtol, atol=atol, use_jac=use_jac)
        out.append(states)
        nfev += n
    return out, nfev


def write_fedbatch(path, experiments, runs):
    with open(path, "w", newline="") as h:
        w = csv.writer(h, lineterminator="\n")
        w.writerow(["experiment", "t", "F"] + fm.STATES)
        for e, states in zip(experiments, runs):
            for t, F, y in zip(e["t"], e["F"], states):
                w.writerow([e["name"], f"{t:.2f}", repr(float(F))] + [repr(float(v)) for v in y])


def read_fedbatch(path):
    """{experiment: (t array, states array)} of a reference CSV."""
    out = {}
    with open(path, newline="") as h:
        for row in csv.DictReader(h):
            e = out.setdefault(row["experiment"], ([], []))
            e[0].append(float(row["t"]))
            e[1].append([float(row[s]) for s in fm.STATES])
    return {k: (np.array(t), np.array(y)) for k, (t, y) in out.items()}


def max_rel_error(runs, refs, names=fm.STATES, floors=FLOORS):
    """Per state: max over rows of |a - b| / max(|b|, floor)."""
    err = {}
    for k, s in enumerate(names):
        worst = 0.0
        for a, b in zip(runs, refs):
            d = np.abs(a[:, k] - b[:, k]) / np.maximum(np.abs(b[:, k]), floors[s])
            worst = max(worst, float(np.max(d)))
        err[s] = worst
    return err


def write_feeds(experiments, folder=HERE / "feeds"):
    folder.mkdir(exist_ok=True)
    paths = {}
    for e in experiments:
        path = folder / f"{e['name']}.csv"
        with open(path, "w", newline="") as h:
            w = csv.writer(h, lineterminator="\n")
            w.writerow(["t", "F"])
            for t, F in fm.feed_file_rows(e["breaks"], e["levels"], e["t"][-1]):
                w.writerow([f"{t:g}", f"{F:g}"])
        paths[e["name"]] = path.relative_to(fm.ROOT)
    return paths


def write_params_file(path, params):
    Path(path).write_text(json.dumps({"fitted_params": params}, indent=1) + "\n")


def fedbatch_commands(experiments, gbc="target/release/gbc", params_file=None, rtol=1e-10,
                      atol=1e-14, feeds=None):
    """Per experiment: (name, t_end, command) of the gbc run that matches (b)."""
    decl = fm.declared()
    feeds = feeds or {e["name"]: Path("bench/stiff/feeds") / f"{e['name']}.csv" for e in experiments}
    out = []
    for e in experiments:
        y0 = fm.start_state(e, decl["init"])
        inits = " ".join(f"--init {s}={float(v)!r}" for s, v in zip(fm.STATES, y0))
        extra = f" --params {params_file}" if params_file else ""
        cmd = (f"{gbc} simulate models/stiff/fedbatch.gbm --t-start {e['t'][0]:g} "
               f"--t-end {e['t'][-1]:g} --dt {GBC_DT:g} --input 'F=csv({feeds[e['name']]})' "
               f"{inits}{extra} --rtol {rtol:g} --atol {atol:g} -o {e['name']}.csv")
        out.append((e["name"], float(e["t"][-1]), cmd))
    return out


def stiffness(experiments, runs, params):
    """Largest |eigenvalue| of the Jacobian at the record rows of the fed phase (F > 0), in
    1/h: median and max over rows, and max times the run length (the stiffness ratio
    against the slowest time scale of interest, the run itself)."""
    model = fm.FedBatch(params, fm.declared()["consts"])
    lams, spans = [], []
    for e, states in zip(experiments, runs):
        spans.append(e["t"][-1] - e["t"][0])
        for F, y in zip(e["F"], states):
            if F > 0:
                lams.append(float(np.max(np.abs(np.linalg.eigvals(model.jac(0.0, y, F))))))
    lams = np.array(lams)
    return {"lambda_median_per_h": float(np.median(lams)), "lambda_max_per_h": float(lams.max()),
            "time_constant_median_s": 3600.0 / float(np.median(lams)),
            "time_constant_min_s": 3600.0 / float(lams.max()),
            "run_h": float(np.median(spans)),
            "lambda_max_times_run": float(lams.max() * np.median(spans))}


# ---------------------------------------------------------------------------------------
# Timing


TIMED = [
    ("LSODA", 1e-6, True),
    ("LSODA", 1e-8, True),
    ("Radau", 1e-6, True),
    ("Radau", 1e-6, False),
]


def robertson_timing(repeats, reference):
    rows = []
    for method, rtol in (("LSODA", 1e-6), ("LSODA", 1e-8), ("Radau", 1e-6), ("Radau", 1e-10)):
        walls = []
        atol = [rtol * 1e-4, rtol * 1e-8, rtol * 1e-8]
        for _ in range(repeats):
            start = time.perf_counter()
            sol = solve_ivp(robertson_rhs, (0.0, ROBERTSON_TIMES[-1]), [1.0, 0.0, 0.0],
                            method=method, t_eval=ROBERTSON_TIMES, rtol=rtol, atol=atol,
                            jac=robertson_jac)
            walls.append(time.perf_counter() - start)
        err = max_rel_error([sol.y.T], [reference], ["y1", "y2", "y3"], ROBERTSON_FLOORS)
        row = {"params": "robertson", "method": method, "rtol": rtol, "atol": atol,
               "jacobian": "analytic", "median_s": statistics.median(walls), "runs_s": walls,
               "nfev": int(sol.nfev), "max_rel_error": err}
        rows.append(row)
        print(f"  robertson   {method:6s} rtol {rtol:g} analytic           "
              f"{row['median_s']:8.3f} s  nfev {sol.nfev:7d}  max rel err "
              + " ".join(f"{k} {v:.1e}" for k, v in err.items()), file=sys.stderr, flush=True)
    return rows


def timing(experiments, repeats, refs):
    rows = []
    for label, ks in (("declared", None), ("K_S=2.7e-6", SMALL_KS)):
        params = params_with(ks)
        for method, rtol, use_jac in TIMED:
            walls = []
            for _ in range(repeats):
                start = time.perf_counter()
                runs, nfev = run_all(experiments, params, method=method, rtol=rtol, atol=1e-12,
                                     use_jac=use_jac)
                walls.append(time.perf_counter() - start)
            err = max_rel_error(runs, refs[label])
            row = {"params": label, "method": method, "rtol": rtol, "atol": 1e-12,
                   "jacobian": "analytic" if use_jac else "finite differences",
                   "median_s": statistics.median(walls), "runs_s": walls, "nfev": nfev,
                   "max_rel_error": err}
            rows.append(row)
            print(f"  {label:11s} {method:6s} rtol {rtol:g} {row['jacobian']:18s} "
                  f"{row['median_s']:8.3f} s  nfev {nfev:7d}  max rel err "
                  + " ".join(f"{s} {v:.1e}" for s, v in err.items()), file=sys.stderr, flush=True)
    return rows


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--record", default=str(fm.RECORD))
    ap.add_argument("--repeats", type=int, default=5, help="timing runs per config (median)")
    ap.add_argument("--no-timing", action="store_true")
    ap.add_argument("--check", action="store_true",
                    help="also rerun (b) at rtol 1e-12 and report the reference's own error")
    ap.add_argument("--seed", type=int, default=0, help="unused: nothing here is random")
    ap.add_argument("--gbc", default="target/release/gbc", help="binary named in the printed commands")
    args = ap.parse_args()
    meta = {}

    # (a) Robertson
    ys, sol = robertson()
    fine, _ = robertson(rtol=1e-12, atol=[1e-16, 1e-20, 1e-20])
    err = max_rel_error([ys], [fine], ["y1", "y2", "y3"], ROBERTSON_FLOORS)
    with open(HERE / "robertson_reference.csv", "w", newline="") as h:
        w = csv.writer(h, lineterminator="\n")
        w.writerow(["t", "y1", "y2", "y3"])
        for t, y in zip(ROBERTSON_TIMES, ys):
            w.writerow([f"{t:g}"] + [repr(float(v)) for v in y])
    meta["robertson"] = {"rtol": 1e-10, "atol": ROBERTSON_ATOL, "nfev": int(sol.nfev),
                         "njev": int(sol.njev), "nlu": int(sol.nlu),
                         "error_vs_rtol_1e-12": err}
    print(f"(a) Robertson: {len(ROBERTSON_TIMES)} times, nfev {sol.nfev}; estimated error "
          + " ".join(f"{k} {v:.1e}" for k, v in err.items()), file=sys.stderr)
    print("gbc (one run per output time; compare.py runs them):")
    for _, cmd in robertson_commands(args.gbc):
        print("  " + cmd)

    # (b) the fed-batch
    experiments = fm.read_record(args.record)
    refs = {}
    for label, ks, name in (("declared", None, "fedbatch_reference.csv"),
                            ("K_S=2.7e-6", SMALL_KS, "fedbatch_reference_ks2.7e-6.csv")):
        start = time.perf_counter()
        runs, nfev = run_all(experiments, params_with(ks))
        wall = time.perf_counter() - start
        write_fedbatch(HERE / name, experiments, runs)
        refs[label] = runs
        entry = {"file": f"bench/stiff/{name}", "params": params_with(ks), "rtol": 1e-10,
                 "atol": 1e-14, "nfev": nfev, "wall_s": wall,
                 "stiffness_fed_phase": stiffness(experiments, runs, params_with(ks))}
        if args.check:
            fine, _ = run_all(experiments, params_with(ks), rtol=1e-12, atol=1e-16)
            entry["error_vs_rtol_1e-12"] = max_rel_error(runs, fine)
        meta[label] = entry
        print(f"(b) fed-batch, {label}: {sum(len(e['t']) for e in experiments)} rows of "
              f"{len(experiments)} batches, nfev {nfev}, {wall:.1f} s"
              + ("; estimated error " + " ".join(f"{k} {v:.1e}" for k, v in entry["error_vs_rtol_1e-12"].items())
                 if args.check else ""), file=sys.stderr)
        st = entry["stiffness_fed_phase"]
        print(f"    fed phase: |lambda|max median {st['lambda_median_per_h']:.3g} /h, max "
              f"{st['lambda_max_per_h']:.3g} /h (time constants {st['time_constant_median_s']:.3g} s, "
              f"{st['time_constant_min_s']:.3g} s); max * run = {st['lambda_max_times_run']:.3g}",
              file=sys.stderr)
    feeds = write_feeds(experiments)
    write_params_file(HERE / "params_ks2.7e-6.json", params_with(SMALL_KS))
    print("gbc, declared params (one run per batch):")
    for _, _, cmd in fedbatch_commands(experiments, args.gbc, feeds=feeds):
        print("  " + cmd)
    print("gbc, K_S = 2.7e-6 g/L: the same with --params bench/stiff/params_ks2.7e-6.json")

    # (c) timing
    if not args.no_timing:
        print(f"(c) timing, median of {args.repeats}, all {len(experiments)} batches:", file=sys.stderr)
        rows = robertson_timing(args.repeats, ys) + timing(experiments, args.repeats, refs)
        doc = {
            "what": "scipy wall time to integrate every batch of models/stiff/data/fedbatch.csv "
                    "at its record times, restarted at every feed change (median of repeats)",
            "python": sys.version.split()[0], "numpy": np.__version__,
            "scipy": __import__("scipy").__version__,
            "error_floors": FLOORS, "rows": rows, "references": meta,
        }
        (HERE / "timing_scipy.json").write_text(json.dumps(doc, indent=1) + "\n")
        print()
        print("| case | method | rtol | Jacobian | median wall [s] | rhs evals | max rel error |")
        print("|---|---|---|---|---|---|---|")
        for r in rows:
            e = " / ".join(f"{k} {v:.1e}" for k, v in r["max_rel_error"].items() if k != "V")
            print(f"| {r['params']} | {r['method']} | {r['rtol']:g} | {r['jacobian']} | "
                  f"{r['median_s']:.3f} | {r['nfev']} | {e} |")
    (HERE / "reference_meta.json").write_text(json.dumps(meta, indent=1) + "\n")


if __name__ == "__main__":
    main()
