#!/usr/bin/env python3
"""Runs gbc on the stiff cases and compares it with the scipy references of reference.py.

Cases (--cases, comma-separated; default all):
  robertson    models/stiff/robertson.gbm, one `gbc simulate --t-end T --dt T` per output
               time of bench/stiff/robertson_reference.csv (gbc's grid is linear)
  declared     models/stiff/fedbatch.gbm with its declared params, one run per batch of
               models/stiff/data/fedbatch.csv (feed from bench/stiff/feeds/<batch>.csv,
               initial state from the batch's first row), against
               bench/stiff/fedbatch_reference.csv at every record time
  ks           the same with K_S = 2.7e-6 g/L (--params bench/stiff/params_ks2.7e-6.json)
               against bench/stiff/fedbatch_reference_ks2.7e-6.csv

Errors: per state, max over the compared times of |gbc - ref| / max(|ref|, floor), floors
X, P 1e-6 g/L, S 1e-8 g/L, V 1e-6 L; y1, y3 1e-12, y2 1e-16 (reference.py FLOORS). S is
~1e-20 g/L once the sugar runs out; below 1e-8 g/L its error is the integrators' atol.
Timing: each gbc command's wall time (the process, start to exit), summed per case, next
to scipy's medians from bench/stiff/timing_scipy.json. A command past --timeout is killed
and reported; by default the rest of that case is skipped (--keep-going runs them all).

Exit status 1 when a case timed out, failed, or exceeded --tolerance (default 1e-5).
Run reference.py first (it writes the references, the feed files and the params file).
numpy + scipy only.
"""

import argparse
import csv
import json
import shlex
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
import fbmodel as fm  # noqa: E402
import reference as ref  # noqa: E402


def run(cmd, cwd, timeout):
    start = time.perf_counter()
    try:
        proc = subprocess.run(shlex.split(cmd), cwd=cwd, capture_output=True, text=True,
                              timeout=timeout)
    except subprocess.TimeoutExpired:
        return "timeout", time.perf_counter() - start, ""
    wall = time.perf_counter() - start
    if proc.returncode != 0:
        return "failed", wall, (proc.stderr or proc.stdout).strip()[-2000:]
    return "ok", wall, ""


def read_gbc(path, names):
    with open(path, newline="") as h:
        rows = list(csv.DictReader(h))
    t = np.array([float(r["t"]) for r in rows])
    y = np.array([[float(r[n]) for n in names] for r in rows])
    return t, y


def robertson_case(args, work):
    with open(HERE / "robertson_reference.csv", newline="") as h:
        rows = list(csv.DictReader(h))
    refs = {float(r["t"]): [float(r[k]) for k in ("y1", "y2", "y3")] for r in rows}
    got, want, walls, status = [], [], [], "ok"
    for T, cmd in ref.robertson_commands(str(args.gbc), args.robertson_rtol, args.robertson_atol):
        cmd = cmd.replace(f"-o robertson_{T:g}.csv", f"-o {work / f'robertson_{T:g}.csv'}")
        state, wall, message = run(cmd, fm.ROOT, args.timeout)
        walls.append(wall)
        print(f"  robertson T={T:g}: {state} {wall:.3f} s {message}", file=sys.stderr, flush=True)
        if state != "ok":
            status = state
            if not args.keep_going:
                break
            continue
        t, y = read_gbc(work / f"robertson_{T:g}.csv", ["y1", "y2", "y3"])
        assert abs(t[-1] - T) <= 1e-9 * T, (t[-1], T)
        got.append(y[-1])
        want.append(refs[T])
    err = (ref.max_rel_error([np.array(got)], [np.array(want)], ["y1", "y2", "y3"],
                             ref.ROBERTSON_FLOORS) if got else None)
    return {"case": "robertson", "status": status, "runs": len(got),
            "runs_expected": len(refs) - 1, "gbc_wall_s": sum(walls),
            "gbc_wall_longest_s": max(walls) if walls else None, "max_rel_error": err}


def fedbatch_case(args, work, label, ks, ref_file, params_file):
    experiments = fm.read_record(args.record)
    refs = ref.read_fedbatch(HERE / ref_file)
    got, want, walls, status, done = [], [], [], "ok", 0
    for name, t_end, cmd in ref.fedbatch_commands(experiments, str(args.gbc), params_file,
                                                  args.rtol, args.atol):
        cmd = cmd.replace(f"-o {name}.csv", f"-o {work / (name + '.csv')}")
        state, wall, message = run(cmd, fm.ROOT, args.timeout)
        walls.append(wall)
        print(f"  {label} {name}: {state} {wall:.3f} s {message}", file=sys.stderr, flush=True)
        if state != "ok":
            status = state
            if not args.keep_going:
                break
            continue
        t, y = read_gbc(work / f"{name}.csv", fm.STATES)
        rt, ry = refs[name]
        index = np.rint(rt / ref.GBC_DT).astype(int)
        assert np.allclose(t[index], rt, atol=1e-6), name
        got.append(y[index])
        want.append(ry)
        done += 1
    err = ref.max_rel_error(got, want) if got else None
    return {"case": label, "status": status, "runs": done, "runs_expected": len(experiments),
            "gbc_wall_s": sum(walls), "max_rel_error": err}


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--gbc", type=Path, default=fm.ROOT / "target/release/gbc")
    ap.add_argument("--cases", default="robertson,declared,ks")
    ap.add_argument("--timeout", type=float, default=120.0, help="seconds per gbc command")
    ap.add_argument("--keep-going", action="store_true")
    ap.add_argument("--rtol", type=float, default=1e-10, help="gbc --rtol for the fed-batch")
    ap.add_argument("--atol", type=float, default=1e-14, help="gbc --atol for the fed-batch")
    ap.add_argument("--robertson-rtol", type=float, default=1e-10)
    ap.add_argument("--robertson-atol", type=float, default=1e-16)
    ap.add_argument("--tolerance", type=float, default=1e-5)
    ap.add_argument("--record", default=str(fm.RECORD))
    ap.add_argument("--json", help="write the results here")
    ap.add_argument("--seed", type=int, default=0, help="unused: nothing here is random")
    args = ap.parse_args()
    args.gbc = args.gbc.resolve()

    results = []
    with tempfile.TemporaryDirectory(prefix="gbc-stiff-") as tmp:
        work = Path(tmp)
        for case in args.cases.split(","):
            print(f"{case}:", file=sys.stderr, flush=True)
            if case == "robertson":
                results.append(robertson_case(args, work))
            elif case == "declared":
                results.append(fedbatch_case(args, work, "declared", None,
                                             "fedbatch_reference.csv", None))
            elif case == "ks":
                results.append(fedbatch_case(args, work, "K_S=2.7e-6", ref.SMALL_KS,
                                             "fedbatch_reference_ks2.7e-6.csv",
                                             "bench/stiff/params_ks2.7e-6.json"))
            else:
                sys.exit(f"unknown case {case}")

    scipy = {}
    timing = HERE / "timing_scipy.json"
    if timing.exists():
        for r in json.loads(timing.read_text())["rows"]:
            key = f"{r['method']} rtol {r['rtol']:g}" + ("" if r["jacobian"] == "analytic" else " (FD jac)")
            scipy.setdefault(r["params"], {})[key] = r["median_s"]

    print()
    print("| case | status | runs | gbc wall [s] | max rel error | scipy medians [s] |")
    print("|---|---|---|---|---|---|")
    failed = False
    for r in results:
        err = r["max_rel_error"]
        err_text = " ".join(f"{k} {v:.1e}" for k, v in err.items()) if err else "-"
        sc = scipy.get(r["case"], {})
        sc_text = ", ".join(f"{k}: {v:.3g}" for k, v in sc.items()) if sc else "-"
        print(f"| {r['case']} | {r['status']} | {r['runs']}/{r['runs_expected']} | "
              f"{r['gbc_wall_s']:.2f} | {err_text} | {sc_text} |")
        r["scipy_median_s"] = sc
        if r["status"] != "ok" or r["runs"] < r["runs_expected"] or (
                err and max(err.values()) > args.tolerance):
            failed = True
    if args.json:
        Path(args.json).write_text(json.dumps({"timeout_s": args.timeout, "results": results}, indent=1) + "\n")
    sys.exit(1 if failed else 0)


if __name__ == "__main__":
    main()
