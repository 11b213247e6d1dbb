#!/usr/bin/env python3
"""The Markdown tables of bench/diagnose/lab_cases.md from the cases' <case>_reference.json
(reference_summary.py): per case, gbc's training gap of each fit next to scipy's best, and
one summary table (batches, rows, gap before / noise floor, verdict, gbc's time).

  python bench/diagnose/lab_cases_tables.py [CASE ...]   (default: overflow hidden_biomass campaign)
"""

import json
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent


def g(v, digits=10):
    return "n/a" if v is None else f"{v:.{digits}g}"


def verdict(run):
    if run["credited"]:
        return "credited " + " + ".join(run["credited"])
    if run.get("undecided"):
        return "undecided: " + " / ".join(run["undecided"])
    return "nothing credited"


def main():
    cases = sys.argv[1:] or ["overflow", "hidden_biomass", "campaign"]
    docs = {c: json.loads((HERE / f"{c}_reference.json").read_text()) for c in cases}
    for case, d in docs.items():
        print(f"### {case}\n")
        print("| fit | gbc gap | scipy gap | rel. diff | gbc s | scipy s | gbc pins |")
        print("|---|---|---|---|---|---|---|")
        for x in d["training_gap"]:
            pins = ", ".join(f"{k} = {v:.4g}" for k, v in x["pinned_gbc"].items()) or "-"
            secs = f"{x['seconds_gbc']:.2f}" if x["seconds_gbc"] is not None else "(in selection)"
            print(f"| {x['fit']} | {g(x['train_gap_gbc'])} | {g(x['train_gap_scipy'])} | "
                  f"{x['relative_difference']:+.2e} | {secs} | {x['seconds_scipy']:.0f} | {pins} |")
        print()
    print("### Summary\n")
    print("| case | batches | rows (train + scored) | gap before / noise floor | verdict | total gbc time |")
    print("|---|---|---|---|---|---|")
    for case, d in docs.items():
        gb = d["gbc"]
        record = (HERE.parents[1] / d["record"]).read_text().splitlines()
        header = record[0].split(",")
        batches = len({line.split(",")[header.index("experiment")] for line in record[1:] if line.strip()}) \
            if "experiment" in header else 1
        rows = gb["split"]["train_rows"] + gb["split"]["test_rows"]
        runs = d.get("seeds") or [{"seed": None, **gb, "wall_s": gb["wall_s"]}]
        verdicts = "; ".join((f"seed {r['seed']}: " if r["seed"] is not None else "") + verdict(r) for r in runs)
        if len({verdict(r) for r in runs}) == 1 and len(runs) > 1:
            verdicts = f"seeds {', '.join(str(r['seed']) for r in runs)}: {verdict(runs[0])}"
        times = ", ".join(f"{r['timing']['total']:.1f} s" for r in runs)
        print(f"| {case} | {batches} | {rows} ({gb['split']['train_rows']} + {gb['split']['test_rows']}) | "
              f"{gb['gap_before']:.4g} / {gb['noise_floor']:.4g} ({gb['gap_before'] / gb['noise_floor']:.1f}x) | "
              f"{verdicts} | {times} ({gb['timing']['jobs']} threads) |")


if __name__ == "__main__":
    main()
