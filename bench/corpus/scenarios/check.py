#!/usr/bin/env python3
"""Checks of the scenario records against gbc (not needed to use them; run after
generate.py):

1. every model.gbm, greybox.gbm and truth.gbm passes `gbc check` and `gbc fmt --check`;
2. truth.gbm, simulated by gbc (`gbc simulate`, batch B1's input programme read from
   data.csv), reproduces generate.py's scipy trajectory of B1;
3. model.gbm with its params at the truth's values, its guessed consts and starts put back
   to the truth's (`answer.guesses`) and the withheld effects applied (`--effect`)
   reproduces truth.gbm: the effects' text is the mechanism the truth has;
4. model.gbm and greybox.gbm declare the same consts, hidden starts and noise; each is the
   truth's (truth.json) except the guesses of `answer.guesses`, which are what the models
   declare, and each of which is 20-50 % off the truth.

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


def declarations(text):
    """The top-level consts, hidden starts (a number or a const's name) and noise lines
    (relative, absolute) of a model text."""
    consts = {m[1]: float(m[2]) for m in re.finditer(r"^const (\w+) = ([0-9.eE+-]+) \[", text, re.M)}
    hidden = {m[1]: m[2] for m in re.finditer(r"^hidden (\w+) \[[^\]]*\] = (\S+)", text, re.M)}
    noise = {}
    for m in re.finditer(r"^noise (\w+) = (.*)$", text, re.M):
        rel = ab = 0.0
        for term in m[2].split(" + "):
            if term.endswith(" %"):
                rel = float(term[:-2]) / 100
            else:
                ab = float(term.split(" [")[0])
        noise[m[1]] = (rel, ab)
    return consts, hidden, noise


def same(a, b):
    """Two (relative, absolute) noise pairs equal to the printing of a percentage."""
    return all(abs(x - y) <= 1e-12 * max(abs(x), abs(y)) for x, y in zip(a, b))


def off(declared, truth):
    """Whether a guess is 20-50 % off the truth (to rounding of the printed numbers)."""
    return 0.2 - 1e-9 <= abs(declared / truth - 1.0) <= 0.5 + 1e-9


def check_guesses(p, d, case, truth):
    """Check 4: the declared consts, starts and noise against the truth and the guesses."""
    problems = []
    g = case["answer"].get("guesses")
    if bool(g) != p["with_guesses"]:
        problems.append(f"answer.guesses is {'present' if g else 'absent'}, the plan says otherwise")
    g = g or {"noise": {}, "starts": {}, "consts": {}}
    T = truth["truth_consts"]
    decl = {f: declarations((d / f).read_text()) for f in ("model.gbm", "greybox.gbm")}
    if decl["model.gbm"] != decl["greybox.gbm"]:
        problems.append("model.gbm and greybox.gbm declare different consts, hidden starts or noise")
    consts, hidden, noise = decl["model.gbm"]
    guessed = dict(g["consts"])
    for state, v in g["starts"].items():
        if "const" in v:
            guessed[v["const"]] = v
        elif not (state in hidden and float(hidden[state]) == v["declared"]):
            problems.append(f"hidden {state} starts at {hidden.get(state)}, not its guess {v['declared']}")
    for name, v in consts.items():
        if name in guessed:
            if v != guessed[name]["declared"] or T[name] != guessed[name]["truth"]:
                problems.append(f"const {name} = {v}: the guess is {guessed[name]}, the truth {T[name]}")
        elif v != T[name]:
            problems.append(f"const {name} = {v} is not the truth's {T[name]} and not a guess")
    for name in guessed:
        if name not in consts:
            problems.append(f"guessed const {name} is not a const of model.gbm")
    b0 = truth["batches"][0]["initial_state"]
    for state, v in hidden.items():
        value = consts[v] if v in consts else float(v)
        want = g["starts"][state]["declared"] if state in g["starts"] else b0[state]
        if value != want:
            problems.append(f"hidden {state} starts at {value}, expected {want}")
    if set(g["starts"]) - set(hidden):
        problems.append(f"guessed starts of states that are not hidden: {set(g['starts']) - set(hidden)}")
    per_state = truth["noise"]["per_state"]
    if set(noise) != (set(per_state) if truth["noise"]["declared"] else set()):
        problems.append(f"noise declared for {sorted(noise)}, the record's is {truth['noise']}")
    if g["noise"] and set(g["noise"]) != set(noise):
        problems.append(f"guessed noise of {sorted(g['noise'])}, declared for {sorted(noise)}")
    for s, (rel, ab) in noise.items():
        t = per_state[s]
        if s in g["noise"]:
            v = g["noise"][s]
            if not same((rel, ab), (v["declared"]["relative"], v["declared"]["absolute"])) or v["truth"] != t:
                problems.append(f"noise {s} = {rel} rel + {ab} abs: the guess is {v}, the truth {t}")
        elif not same((rel, ab), (t["relative"], t["absolute"])):
            problems.append(f"noise {s} = {rel} rel + {ab} abs is not the truth's {t} and not a guess")
    # every guess 20-50 % off the truth
    values = [(f"const {n}", v["declared"], v["truth"]) for n, v in g["consts"].items()]
    values += [(f"start of {n}", v["declared"], v["truth"]) for n, v in g["starts"].items()]
    for s, v in g["noise"].items():
        for k in ("relative", "absolute"):
            values.append((f"{k} noise of {s}", v["declared"][k], v["truth"][k]))
    values = [x for x in values if x[1] or x[2]]  # a noise term neither declares
    for what, dv, tv in values:
        if tv == 0.0 or not off(dv, tv):
            problems.append(f"{what}: the guess {dv} is not 20-50 % off the truth {tv}")
    return problems, len(values)


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
                # the modeller's guesses put back to the truth: the balances are what is checked
                g = case["answer"].get("guesses") or {"starts": {}, "consts": {}}
                for name, v in list(g["consts"].items()) + [(v.get("const"), v) for v in g["starts"].values()]:
                    if name:
                        text, n = re.subn(rf"^(const {name} = )[0-9.eE+-]+", rf"\g<1>{gen.num(v['truth'])}",
                                          text, flags=re.M)
                        assert n == 1, (p["id"], name)
                for state, v in g["starts"].items():
                    if "const" not in v:
                        text, n = re.subn(rf"^(hidden {state} \[[^\]]*\] = )[0-9.eE+-]+",
                                          rf"\g<1>{gen.num(v['truth'])}", text, flags=re.M)
                        assert n == 1, (p["id"], state)
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
        # 4. the declarations: the truth's, or the guesses 20-50 % off it
        more, n_guesses = check_guesses(p, d, case, truth)
        problems += more
        print(f"{p['id']}: {'ok' if not problems else 'FAILED'} (truth.gbm vs scipy {w_truth:.1e}, "
              f"model + {'+'.join(case['answer']['withheld']) or 'no effect'} vs truth.gbm {worst:.1e}; "
              f"without: {moved:.1e}; {n_guesses} guessed values)", flush=True)
        for x in problems:
            print("   " + x.replace("\n", "\n   "))
        bad += bool(problems)
    sys.exit(1 if bad else 0)


if __name__ == "__main__":
    main()
