#!/usr/bin/env python3
"""Checks of the scenario records against gbc (not needed to use them; run after
generate.py):

1. every model.gbm, greybox.gbm and truth.gbm passes `gbc check` and `gbc fmt --check`;
2. truth.gbm, simulated by gbc (`gbc simulate`, batch B1's input programme read from
   data.csv), reproduces generate.py's scipy trajectory of B1;
3. model.gbm with its params at the truth's values and the withheld effects applied
   (`--effect`) reproduces truth.gbm: the effects' text is the mechanism the truth has.

    python3 bench/corpus/scenarios/check.py [--gbc PATH] [--only s01 s02]

numpy + scipy, and a gbc binary (default target/release/gbc).
"""

import argparse
import csv
import json
import re
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

import generate as gen

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[2]


def run(cmd):
    return subprocess.run(cmd, capture_output=True, text=True, timeout=300)


def read_sim(path):
    with open(path) as h:
        rows = list(csv.DictReader(h))
    return {k: np.array([float(r[k]) for r in rows]) for k in rows[0]}


def simulate(gbc, model, t_end, dt, inputs, data, extra, out):
    cmd = [gbc, "simulate", str(model), "--t-end", repr(t_end), "--dt", repr(dt), "-o", str(out),
           "--rtol", "1e-9"]
    for u in inputs:
        cmd += ["--input", f"{u}=csv({data}, {u}, experiment=B1)"]
    r = run(cmd + extra)
    if r.returncode:
        raise RuntimeError(" ".join(cmd + extra) + "\n" + r.stderr[-2000:])
    return read_sim(out)


def rel_err(a, b, scale):
    return float(np.max(np.abs(a - b)) / scale)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--gbc", default=str(ROOT / "target/release/gbc"))
    ap.add_argument("--only", nargs="*")
    args = ap.parse_args()
    bad = 0
    for p in gen.plan():
        if args.only and p["id"] not in args.only:
            continue
        d = HERE / p["id"]
        case = json.loads((d / "case.json").read_text())
        truth = json.loads((d / "truth.json").read_text())
        problems = []
        for f in ("model.gbm", "greybox.gbm", "truth.gbm"):
            for cmd in (["check"], ["fmt", "--check"]):
                r = run([args.gbc, *cmd, str(d / f)])
                if r.returncode:
                    problems.append(f"gbc {' '.join(cmd)} {f}: {r.stdout[-500:]}{r.stderr[-1500:]}")
        # 2. truth.gbm by gbc against scipy, batch B1
        sc, fam, rng, sim, truth_model = gen.setup(p)
        b1 = truth["batches"][0]
        inputs = sim.inputs
        breaks = b1["input_breaks"]
        levels = [[b1["input_levels"][u][k] for u in inputs] for k in range(len(breaks))]
        y0 = [b1["initial_state"][s] for s in sim.states]
        t_end, dt = b1["t_end"], 0.25
        grid = np.round(np.arange(0.0, t_end + 1e-9, dt), 6)
        ref = sim.sample(y0, breaks, levels, grid)
        w_truth = worst = moved = float("nan")
        with tempfile.TemporaryDirectory() as tmp:
            tmp = Path(tmp)
            try:
                g = simulate(args.gbc, d / "truth.gbm", t_end, dt, inputs, d / "data.csv", ["--hidden"],
                             tmp / "truth.csv")
                worst = 0.0
                for k, s in enumerate(sim.states):
                    scale = max(np.max(np.abs(ref[:, k])), 1e-3)
                    worst = max(worst, rel_err(g[s][: len(grid)], ref[:, k], scale))
                assert len(g["t"]) == len(grid), (len(g["t"]), len(grid))
                w_truth = worst
                if worst > 1e-5:
                    problems.append(f"truth.gbm by gbc differs from scipy by {worst:.2e} (of the range)")
                # 3. model + withheld effects at the truth's params == truth
                text = (d / "model.gbm").read_text()
                for name, v in case["answer"]["params"].items():
                    text, n = re.subn(rf"^(\s*param {name} = )[0-9.eE+-]+", rf"\g<1>{gen.num(v)}", text, flags=re.M)
                    assert n == 1, (p["id"], name)
                (tmp / "at_truth.gbm").write_text(text)
                extra = ["--hidden"] + [a for w in case["answer"]["withheld"] for a in ("--effect", w)]
                extra += [a for s in sc["measured"] for a in ("--init", f"{s}={gen.num(b1['initial_state'][s])}")]
                m = simulate(args.gbc, tmp / "at_truth.gbm", t_end, dt, inputs, d / "data.csv", extra,
                             tmp / "model.csv")
                # how far the withheld mechanism moves B1: the model without it, at the truth
                base = simulate(args.gbc, tmp / "at_truth.gbm", t_end, dt, inputs, d / "data.csv",
                                [a for s in sc["measured"] for a in ("--init", f"{s}={gen.num(b1['initial_state'][s])}")],
                                tmp / "base.csv")
                moved = max(rel_err(base[s], g[s], max(np.max(np.abs(g[s])), 1e-3)) for s in sc["measured"])
                worst = 0.0
                for s in sim.states:
                    if s not in m:
                        continue
                    scale = max(np.max(np.abs(g[s])), 1e-3)
                    worst = max(worst, rel_err(m[s], g[s], scale))
                if worst > 1e-5:
                    problems.append(f"model.gbm + withheld effects at the truth differs from truth.gbm by "
                                    f"{worst:.2e}")
            except RuntimeError as e:
                problems.append(str(e))
        print(f"{p['id']}: {'ok' if not problems else 'FAILED'} (truth.gbm vs scipy {w_truth:.1e}, "
              f"model + {'+'.join(case['answer']['withheld']) or 'no effect'} vs truth.gbm {worst:.1e}; "
              f"without: {moved:.1e})", flush=True)
        for x in problems:
            print("   " + x.replace("\n", "\n   "))
        bad += bool(problems)
    sys.exit(1 if bad else 0)


if __name__ == "__main__":
    main()
