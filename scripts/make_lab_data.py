#!/usr/bin/env python3
"""Makes models/bioreactor/data/lab/: the bioreactor truth as a lab would record it.

Four experiments (run1..run4), each with its own random light programme and its own start
(the culture first settles at the programme's first light level), simulated densely by
`gbc simulate` (every 0.1 h) and then sampled as a lab samples:

- off-line assays of X, A, B, S at irregular times, every 1 to 4 h (uniform, on the 0.1 h
  grid), each cell missing with probability 10 % and carrying 2 % relative Gaussian noise;
- the light u logged only when it changes (its cells are empty at assay rows: the reader
  holds the last logged value);
- headers with units: `t [h]`, `u [-]`, `X [g/L]`, ...

Run from the crate root after `cargo build --release`:
    python3 scripts/make_lab_data.py
"""
import csv, os, random, subprocess, tempfile

GBC = os.environ.get("GBC", "target/release/gbc")
OUT = os.environ.get("OUT", "models/bioreactor/data/lab")
NOISE = float(os.environ.get("NOISE", "0.02"))
MISSING = float(os.environ.get("MISSING", "0.10"))
HOURS = 760.0
EXPERIMENTS = [
    # name, light programme, warm-up (h)
    ("run1", "steps(hold=5..40, seed=11)", 300),
    ("run2", "steps(hold=5..40, seed=12)", 300),
    ("run3", "steps(lo=0.1, hi=0.9, hold=10..60, seed=13)", 300),
    ("run4", "steps(hold=5..40, seed=14)", 300),
]
STATES = ["X", "A", "B", "S"]
UNITS = {"X": "g/L", "A": "g/L", "B": "g/L", "S": "g/L"}


def simulate(programme, warmup, path):
    subprocess.run(
        [GBC, "simulate", "models/bioreactor/truth.gbm", "--t-end", str(HOURS), "--dt", "0.1",
         "--warmup", str(warmup), "--input", f"u={programme}", "-o", path],
        check=True,
    )
    with open(path) as f:
        return list(csv.DictReader(f))


def main():
    os.makedirs(OUT, exist_ok=True)
    for index, (name, programme, warmup) in enumerate(EXPERIMENTS):
        rng = random.Random(100 + index)
        with tempfile.TemporaryDirectory() as tmp:
            dense = simulate(programme, warmup, os.path.join(tmp, "dense.csv"))
        # Dense rows are 0.1 h apart: index k is time k / 10.
        assays, k = set(), 0
        while k < len(dense):
            assays.add(k)
            k += rng.randint(10, 40)
        changes = {0} | {k for k in range(1, len(dense)) if dense[k]["u"] != dense[k - 1]["u"]}
        rows = []
        for k in sorted(assays | changes):
            row = {"t [h]": f"{k / 10:.1f}", "u [-]": dense[k]["u"] if k in changes else ""}
            for state in STATES:
                cell = ""
                if k in assays and rng.random() >= MISSING:
                    value = float(dense[k][state]) * (1.0 + NOISE * rng.gauss(0.0, 1.0))
                    cell = f"{value:.6g}"
                row[f"{state} [{UNITS[state]}]"] = cell
            rows.append(row)
        path = os.path.join(OUT, f"{name}.csv")
        with open(path, "w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=list(rows[0].keys()))
            writer.writeheader()
            writer.writerows(rows)
        print(f"{path}: {len(assays)} assays, {len(changes)} light changes, {len(rows)} rows")


if __name__ == "__main__":
    main()
