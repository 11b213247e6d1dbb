#!/usr/bin/env python3
"""Write data/biolector_yeast.csv from the measured BioLector fed-batches shipped by pseudobatch.

The only writer of data/biolector_yeast.csv (no hand edits). Standard library only. Steps:

1. `python3 -m pip download --no-deps --no-binary :all: pseudobatch==1.0.1 -d CACHE`
   (this script runs it through `registry.fetch`; CACHE defaults to /tmp/gbc-corpus-cache,
   or pass a folder with the sdist already in it as the first argument), and check the
   archive's sha256;
2. read `pseudobatch/datasets/data/biolector_yeast_fedbatch.csv` out of the sdist (what
   `pseudobatch.datasets.load_real_world_yeast_fedbatch()` returns: the loader is a plain
   `pandas.read_csv` of that file);
3. keep the 8 wells of `Yeast_strain_1` and write the columns below.

Run from anywhere: `python3 convert.py [CACHE]`.

The file is the record of one BioLector microbioreactor run: 32 wells, four Saccharomyces
cerevisiae strains (8 wells each), every well fed by the BioLector's microfluidic pump from
about 14.3 h on, one row per measurement cycle (about 6 min). This script keeps the 8 wells
of `Yeast_strain_1` (one parameter set can describe one strain; the other strains are left
in the package; `biolector_yeast_strain2` uses `Yeast_strain_2`) and writes one experiment
per well, named by the well (C01, ..., F02).

Columns, per well, one row per measurement cycle (about 6 min; KEEP_EVERY = 3 would keep
every third), times unchanged, in h since the start of the run:
- `F [uL/h]`: feed rate, the increase of the package's `Accum. feed [uL]` to the next kept
  row divided by the time to it, time-stamped at the start of the interval (held until the
  next row, it delivers exactly the logged feed). The last row repeats the one before.
- `F_smp [uL/h]`: sampling, the package's `Sample volume`s taken in the interval to the next
  kept row (a sample is taken just after its cycle: the volume of the next cycle is 300 uL
  lower) spread over that interval, 0 elsewhere. Every sample is kept, and every row's
  volume is the logged one.
- `V [uL]`: the package's `Volume` (800 uL plus the feed minus the samples; computed by
  the device's software, not measured, evaporation not included).
- `X [-]`: `Biomass concentration [light scatter]`, the on-line scattered-light signal
  (arbitrary units), as measured.
- `DO [%]`: dissolved oxygen from the optode, as measured (it reads above 100 % at the
  start: the device's calibration, left as it is).
No value is changed, smoothed or left out; the flows are differences of logged totals
between the kept rows.
"""
import csv
import io
import os
import sys
import tarfile

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
import registry  # noqa: E402  (bench/corpus/real/registry.py)

PACKAGE = "pseudobatch"
VERSION = "1.0.1"
ARCHIVE = f"{PACKAGE}-{VERSION}.tar.gz"
SHA256 = "0195761761464655f10c85a2c942cac5320d1105f74d63463c65064f93240c4b"
MEMBER = f"{PACKAGE}-{VERSION}/pseudobatch/datasets/data/biolector_yeast_fedbatch.csv"
STRAIN = "Yeast_strain_1"
KEEP_EVERY = 1  # keep every measurement cycle (3: every third, about 18 min)

HERE = os.path.dirname(os.path.abspath(__file__))
OUT = os.path.join(HERE, "data", "biolector_yeast.csv")


def fetch(cache):
    """The package's archive in `cache`, checked (`registry.fetch`)."""
    return registry.fetch(cache, PACKAGE, VERSION, ARCHIVE, SHA256, source=True)


def fmt(v: float, digits: int = 6) -> str:
    s = f"{v:.{digits}g}"
    return "0" if s in ("0", "-0") else s


def main():
    cache = sys.argv[1] if len(sys.argv) > 1 else "/tmp/gbc-corpus-cache"
    with tarfile.open(fetch(cache)) as tar:
        text = tar.extractfile(MEMBER).read().decode("utf-8")
    rows = [r for r in csv.DictReader(io.StringIO(text)) if r["Strain"] == STRAIN]
    lines = ["experiment,t [h],F [uL/h],F_smp [uL/h],V [uL],X [-],DO [%]"]
    for well in sorted({r["Biolector well"] for r in rows}):
        w = sorted((r for r in rows if r["Biolector well"] == well), key=lambda r: float(r["Time"]))
        t = [float(r["Time"]) for r in w]
        acc = [float(r["Accum. feed [uL]"]) for r in w]
        smp = [float(r["Sample volume"]) for r in w]
        vol = [float(r["Volume"]) for r in w]
        n = len(w)
        for i in range(n - 1):
            # The logged volume is the logged feed minus the logged samples.
            expect = vol[i] + (acc[i + 1] - acc[i]) - smp[i]
            assert abs(vol[i + 1] - expect) < 0.01, (well, i, vol[i + 1], expect)
        assert smp[-1] == 0, (well, "a sample at the last row")
        keep = list(range(0, n, KEEP_EVERY))
        if keep[-1] != n - 1:
            keep.append(n - 1)
        feed = []
        out = []
        for a, b in zip(keep[:-1], keep[1:]):
            dt = t[b] - t[a]
            feed.append((acc[b] - acc[a]) / dt)
            out.append(sum(smp[a:b]) / dt)
        feed.append(feed[-1])
        out.append(0.0)
        assert abs(sum(o * (t[b] - t[a]) for o, a, b in zip(out, keep[:-1], keep[1:])) - sum(smp)) < 1e-6
        for j, i in enumerate(keep):
            lines.append(
                ",".join(
                    [
                        well,
                        f"{t[i]:.4f}",
                        fmt(feed[j], 5),
                        fmt(out[j], 5),
                        fmt(vol[i], 7),
                        fmt(float(w[i]["Biomass concentration [light scatter]"]), 4),
                        fmt(float(w[i]["DO%"]), 5),
                    ]
                )
            )
        print(f"{well}: {len(keep)} rows of {n} cycles, {t[0]:.2f}-{t[-1]:.2f} h, {sum(1 for s in smp if s > 0)} samples")
    os.makedirs(os.path.dirname(OUT), exist_ok=True)
    with open(OUT, "w", newline="") as f:
        f.write("\n".join(lines) + "\n")
    print(f"wrote {OUT} ({len(lines) - 1} rows)")


if __name__ == "__main__":
    main()
