#!/usr/bin/env python3
"""A small JSON of one lab-like case's figures (bench/diagnose/<case>_reference.json):
`gbc diagnose` on the case's record with the case's split (timed, its verdict, ranking and
training gaps), next to scipy's reference fits (bench/diagnose/fit_reference.py's JSON,
--fit-json) on the same training split, and the noise check: the gap the truth itself
leaves (the record's noise-free twin, <case>_clean.csv, against the record, z-scored as
gbc does), i.e. what a perfect model would score, per state.

  python bench/diagnose/fit_reference.py --case campaign --json /tmp/campaign_fit.json
  python bench/diagnose/reference_summary.py --case campaign --fit-json /tmp/campaign_fit.json

The training gaps compared: the base fit and each candidate (the report's effects[].fit,
with its seconds and starts) and every set of effects scipy fitted that gbc's selection
also fitted (selection.steps[], gap_train only: the steps carry no per-fit time).
`--seed` runs gbc diagnose once per seed given: the first run gives the figures, every run
its verdict (selection.credited and .undecided) and training gaps (seeds[]).

numpy + scipy + sympy, and a built gbc (target/release/gbc unless --gbc).
"""

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(ROOT / "bench"))
import gbmlib  # noqa: E402
from fit_reference import CASES  # noqa: E402


def noise_check(case, holdout):
    """What a perfect model scores, z-scored as gbc does (each state by the population
    deviation of its training cells), on the training cells and on the scored cells:
    - `measurement`: the record's noise-free twin (<case>_clean.csv) against the record,
      the measurement noise alone;
    - `free_run`: the diagnosed model with the true effects at the true params, run free
      from each experiment's first row as gbc runs it (measured states from their noisy
      cells there): the noise plus what the noisy starts carry along."""
    c = CASES[case]
    truth = json.loads((ROOT / c["truth"]).read_text())
    model = gbmlib.Model(ROOT / c["model"], c["true_set"])
    record = gbmlib.read_record(ROOT / c["record"], model)
    clean = {e["name"]: e for e in gbmlib.read_record(ROOT / c["record"].replace(".csv", "_clean.csv"), model)}
    parts = gbmlib.training_parts(record, holdout, None)
    train_end = {e["name"]: end for e, end in parts}
    pooled = [[] for _ in model.states]
    for e, end in parts:
        for k in range(len(model.states)):
            column = e["cells"][:end, k]
            pooled[k].extend(column[~np.isnan(column)])
    std = np.array([gbmlib.mean_std(v)[1] for v in pooled])

    def summary(cells):  # [(state index, z^2)]
        per = {}
        for k, z in cells:
            per.setdefault(model.states[k], []).append(z)
        return {"gap": float(np.mean([z for _, z in cells])), "cells": len(cells),
                "per_state": {s: float(np.mean(v)) for s, v in per.items()}}

    out = {"measurement": {}, "free_run": {}}
    splits = {"train": lambda e, i: i < train_end.get(e["name"], 0),
              "scored": lambda e, i: i >= train_end.get(e["name"], 0)}
    known = dict(truth["true_effect_params"]["base"])
    for effect in c["true_set"]:
        known.update(truth["true_effect_params"][effect])
    values = [known[n] for n in model.param_names]
    for split, chosen in splits.items():
        cells = []
        for e in record:
            rows, ks = np.nonzero(~np.isnan(e["cells"]))
            for i, k in zip(rows, ks):
                if chosen(e, i):
                    cells.append((k, ((clean[e["name"]]["cells"][i, k] - e["cells"][i, k]) / std[k]) ** 2))
        out["measurement"][split] = summary(cells)
        # the free runs (gbmlib.Problem with gbc's starts, scored on the chosen rows only)
        runs = [(e, len(e["t"])) for e in record if any(chosen(e, i) for i in range(len(e["t"])))]
        problem = gbmlib.Problem(model, runs, "Radau", 1e-10, 1e-12, None)
        for j, (e, times, mask, cells_, starts) in enumerate(problem.parts):
            keep = np.array([chosen(e, i) for i in range(len(times))])
            problem.parts[j] = (e, times, mask & keep[:, None], cells_, starts)
        problem.std = std
        problem.cells = int(sum(m.sum() for _, _, m, _, _ in problem.parts))
        problem.scale = 1.0
        r = problem.residuals(problem.theta0(values))
        ks = np.concatenate([np.nonzero(m)[1] for _, _, m, _, _ in problem.parts])
        out["free_run"][split] = summary(list(zip(ks, r ** 2)))
    out["free_run"]["model"] = f"{c['model']} with {' + '.join(c['true_set'])} at the true params"
    return out


def run_gbc(gbc, case, holdout, jobs, seed=None):
    c = CASES[case]
    with tempfile.TemporaryDirectory() as tmp:
        report = Path(tmp) / "report.json"
        cmd = [gbc, "diagnose", c["model"], c["record"]]
        if holdout:
            cmd += ["--holdout", *holdout]
        if jobs:
            cmd += ["--jobs", str(jobs)]
        if seed is not None:
            cmd += ["--seed", str(seed)]
        shown = " ".join(["gbc", *cmd[1:]])
        t0 = time.perf_counter()
        proc = subprocess.run(cmd + ["--json", str(report)], cwd=ROOT, capture_output=True, text=True)
        wall = time.perf_counter() - t0
        if proc.returncode != 0:
            sys.exit(f"{shown} failed:\n{proc.stderr}")
        return shown, wall, json.loads(report.read_text()), proc.stdout


def binary_identity(gbc):
    """The gbc binary run: its path, size, modification time and SHA-256 (the `commit` field is
    the checkout's HEAD, which a frozen binary elsewhere need not match)."""
    import datetime
    import hashlib
    path = Path(gbc)
    data = path.read_bytes()
    return {"path": str(path), "bytes": len(data), "sha256": hashlib.sha256(data).hexdigest(),
            "modified": datetime.datetime.fromtimestamp(path.stat().st_mtime, datetime.timezone.utc).isoformat()}


def gbc_fit(report, label):
    """gbc's fit of `label` (base, an effect, or a set a+b): the report's base fit or
    effects[].fit (with seconds, starts, estimates), else the selection step of that set
    (its training gap only)."""
    if label == "base":
        return dict(report["base_fit"], source="base_fit")
    for e in report["effects"]:
        if e["name"] == label:
            return dict(e["fit"], source="effects")
    wanted = sorted(label.split("+"))
    for step in report["selection"]["steps"]:
        if sorted(step["effects"]) == wanted:
            return {"gap_train": step["gap_train"], "source": "selection.steps"}
    return None


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--case", required=True, choices=sorted(CASES))
    ap.add_argument("--fit-json", required=True, help="fit_reference.py's output for the case")
    ap.add_argument("--gbc", default=str(ROOT / "target/release/gbc"))
    ap.add_argument("--jobs", type=int, default=None, help="gbc diagnose --jobs (default: every core)")
    ap.add_argument("--out", default=None, help="default bench/diagnose/<case>_reference.json")
    ap.add_argument("--seed", type=int, nargs="+", default=None,
                    help="gbc diagnose --seed, one run per seed (the first gives the figures; default: gbc's)")
    args = ap.parse_args()

    c = CASES[args.case]
    fits = json.loads(Path(args.fit_json).read_text())
    holdout = fits["holdout"]
    assert fits["case"] == args.case and fits["val_fraction"] is None, "the reference fit used another split"
    seeds = args.seed or [None]
    runs = []
    for seed in seeds:
        load_before = os.getloadavg()
        shown, wall, report, text = run_gbc(args.gbc, args.case, holdout, args.jobs, seed)
        load_after = os.getloadavg()
        runs.append({"seed": seed, "command": shown, "wall_s": wall, "report": report, "text": text,
                     "load_average_before": load_before, "load_average_after": load_after})
    shown, wall, report, text = (runs[0][k] for k in ("command", "wall_s", "report", "text"))
    load_before, load_after = runs[0]["load_average_before"], runs[0]["load_average_after"]
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True,
                            text=True).stdout.strip()
    dirty = bool(subprocess.run(["git", "status", "--porcelain", "--", "src", "Cargo.toml", "Cargo.lock"],
                                cwd=ROOT, capture_output=True, text=True).stdout.strip())
    comparison = []
    for f in fits["fits"]:
        g = gbc_fit(report, f["fit"])
        if g is None:
            continue
        s = f["best"]["gap"]
        comparison.append({
            "fit": f["fit"], "source_gbc": g["source"], "train_gap_gbc": g["gap_train"], "train_gap_scipy": s,
            "relative_difference": (g["gap_train"] - s) / s, "gap_at_truth": f["gap_truth"],
            "seconds_gbc": g.get("seconds"), "starts_gbc": g.get("starts"),
            "seconds_scipy": f["wall_s"], "starts_scipy": len(f["starts"]),
            "starts_scipy_reaching_best": f["starts_reaching_best"],
            "pinned_gbc": dict(g.get("pinned") or []),
            "params_gbc": {e["name"]: e["value"] for e in g["estimates"]} if "estimates" in g else None,
            "params_scipy": f["best"]["params"],
            "identified_products_scipy": f["best"].get("identified_products") or None,
        })
        secs = f"{g['seconds']:.1f} s, {g['starts']} starts" if "seconds" in g else "selection step"
        print(f"{f['fit']:28s} training gap gbc {g['gap_train']:.10g} ({secs})"
              f"  scipy {s:.10g} ({f['wall_s']:.0f} s, {len(f['starts'])} starts)"
              f"  rel. diff {(g['gap_train'] - s) / s:+.2e}", file=sys.stderr)
    per_seed = []
    for r in runs:
        rep_, sel = r["report"], r["report"]["selection"]
        per_seed.append({
            "seed": r["seed"], "command": r["command"], "wall_s": r["wall_s"], "timing": rep_["timing"],
            "load_average_before": r["load_average_before"], "load_average_after": r["load_average_after"],
            "credited": sel["credited"], "undecided": sel.get("undecided"), "stop": sel.get("stop"),
            "gap_after_credited": sel["gap_after"],
            "train_gaps": {f["fit"]: (gbc_fit(rep_, f["fit"]) or {}).get("gap_train") for f in fits["fits"]},
        })
    noise = noise_check(args.case, holdout)
    selection = report["selection"]
    doc = {
        "what": f"gbc diagnose on the {args.case} case against scipy's reference fits of the same "
                "training split (bench/diagnose/reference_summary.py)",
        "case": args.case, "model": c["model"], "record": c["record"], "holdout": holdout,
        "true_set": c["true_set"],
        "machine": {"cores": os.cpu_count(), "load_average_before": load_before,
                    "load_average_after": load_after, "platform": platform.platform()},
        "gbc": {
            "command": shown, "commit": commit + ("+dirty" if dirty else ""), "wall_s": wall,
            "binary": binary_identity(args.gbc),
            "timing": report["timing"], "split": {k: report["split"][k] for k in ("train_rows", "test_rows")},
            "gap_before": report["gap_before"], "noise_floor": report["noise_floor"],
            "significant": report["significant"], "credited": selection["credited"],
            "undecided": selection.get("undecided"), "pinned_base": dict(report["base_fit"].get("pinned") or []),
            "gap_after_credited": selection["gap_after"], "stop": selection.get("stop"),
            "noise_floor_per_state": {s["name"]: s["noise"] for s in report["states"]},
            "ranking": [{"effect": e["name"], "gap_after": e["gap_after"], "shrink": e["shrink"],
                         "probability_best": e["probability_best"], "train_gap": e["fit"]["gap_train"]}
                        for e in report["effects"]],
            "first_locus": report["locus"][0] if report["locus"] else None,
        },
        "scipy": {"settings": fits["settings"], "wall_s": fits["wall_s"], "versions": fits["versions"]},
        "training_gap": comparison,
        "seeds": per_seed,
        "noise_check": noise,
    }
    out = Path(args.out) if args.out else HERE / f"{args.case}_reference.json"
    out.write_text(json.dumps(doc, indent=1) + "\n")
    print(text, file=sys.stderr)
    print(f"gbc diagnose {wall:.1f} s, credited {selection['credited'] or 'none'}; a perfect model's gap: "
          f"measurement noise {noise['measurement']['scored']['gap']:.4g} scored "
          f"({noise['measurement']['train']['gap']:.4g} training), free run "
          f"{noise['free_run']['scored']['gap']:.4g} scored ({noise['free_run']['train']['gap']:.4g} training); "
          f"wrote {out}", file=sys.stderr)


if __name__ == "__main__":
    main()
