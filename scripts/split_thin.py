#!/usr/bin/env python3
"""Splits a uniform, complete record into experiments and thins its cells, as the
split/thinned `gbc diagnose` cases do (models/diagnose/README.md).

    python3 scripts/split_thin.py RECORD.csv OUTDIR --inputs u [--experiments 3]
        [--keep 0.3] [--seed 1]

The rows are cut into EXPERIMENTS contiguous pieces of (nearly) equal length, written as
OUTDIR/e1.csv, e2.csv, ... Each piece keeps its first row whole (an experiment starts with
a full assay); at every later row each state cell is kept with probability KEEP, and a row
is written only if it keeps a cell or an input changes there (an input is logged at every
change). Times become irregular and cells missing; inputs are written at every row kept.
The tests do the same in Rust (src/diagnose/tests_sets.rs, `split_and_thin`), with their
own generator: the two give different (equally valid) samples.
"""
import argparse, csv, os, random


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("record")
    parser.add_argument("out")
    parser.add_argument("--inputs", required=True, help="comma-separated input columns")
    parser.add_argument("--experiments", type=int, default=3)
    parser.add_argument("--keep", type=float, default=0.3)
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args()
    with open(args.record) as f:
        rows = list(csv.reader(f))
    header, rows = rows[0], rows[1:]
    inputs = [header.index(name) for name in args.inputs.split(",")]
    states = [i for i in range(1, len(header)) if i not in inputs]
    rng = random.Random(args.seed)
    os.makedirs(args.out, exist_ok=True)
    n = args.experiments
    for e in range(n):
        piece = rows[e * len(rows) // n:(e + 1) * len(rows) // n]
        kept = []
        for k, row in enumerate(piece):
            if k == 0:
                kept.append(row)
                continue
            out = list(row)
            for i in states:
                if rng.random() >= args.keep:
                    out[i] = ""
            changed = any(row[i] != piece[k - 1][i] for i in inputs)
            if changed or any(out[i] != "" for i in states):
                kept.append(out)
        with open(os.path.join(args.out, f"e{e + 1}.csv"), "w", newline="") as f:
            writer = csv.writer(f)
            writer.writerow(header)
            writer.writerows(kept)


if __name__ == "__main__":
    main()
