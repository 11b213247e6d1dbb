#!/usr/bin/env python3
"""Thins a uniform record into a lab-like one: keeps each measured cell with probability
SHARE (states only; inputs are kept at their first row and wherever they change), drops
rows left with nothing, and optionally cuts the record into N experiments (an
`experiment` column, each part its own time axis from 0).

    python3 scripts/thin_record.py IN.csv OUT.csv --share 0.25 --states X,A,B,S \
        --inputs u [--experiments 3] [--seed 1]

Used for the thinned-record comparisons in docs/training.md and docs/diagnose.md.
"""
import argparse, csv, random


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("source")
    parser.add_argument("target")
    parser.add_argument("--share", type=float, required=True)
    parser.add_argument("--states", required=True)
    parser.add_argument("--inputs", default="")
    parser.add_argument("--experiments", type=int, default=1)
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args()
    rng = random.Random(args.seed)
    states = args.states.split(",")
    inputs = [i for i in args.inputs.split(",") if i]
    with open(args.source) as f:
        rows = list(csv.DictReader(f))
    size = -(-len(rows) // args.experiments)
    out = []
    for part in range(args.experiments):
        chunk = rows[part * size:(part + 1) * size]
        if not chunk:
            continue
        start = float(chunk[0]["t"])
        previous = None
        for index, row in enumerate(chunk):
            kept = {s: (row[s] if rng.random() < args.share else "") for s in states}
            changed = index == 0 or any(row[i] != previous[i] for i in inputs)
            previous = row
            if not changed and not any(kept.values()):
                continue
            line = {"t": f"{float(row['t']) - start:g}"}
            line.update({i: (row[i] if changed else "") for i in inputs})
            line.update(kept)
            if args.experiments > 1:
                line = {"experiment": f"part{part + 1}", **line}
            out.append(line)
    with open(args.target, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(out[0].keys()))
        writer.writeheader()
        writer.writerows(out)
    print(f"{args.target}: {len(out)} rows from {len(rows)}")


if __name__ == "__main__":
    main()
