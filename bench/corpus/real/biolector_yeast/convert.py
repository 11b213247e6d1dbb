#!/usr/bin/env python3
"""Write data/biolector_yeast.csv from the measured BioLector fed-batches shipped by pseudobatch.

The only writer of data/biolector_yeast.csv (no hand edits). Steps (SOURCE.md says why):

    python3 -m venv .venv && . .venv/bin/activate
    pip install pseudobatch==1.0.1      # brings numpy and pandas
    python convert.py                   # a second

The package's `pseudobatch.datasets.load_real_world_yeast_fedbatch()` returns the record of
one BioLector microbioreactor run: 32 wells, four Saccharomyces cerevisiae strains (8 wells
each), every well fed by the BioLector's microfluidic pump from about 14.3 h on, one
row per measurement cycle (about 6 min). This script keeps the 8 wells of
`Yeast_strain_1` (one parameter set can describe one strain; the other strains are left
in the package) and writes one experiment per well, named by the well (C01, ..., F02).

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

from __future__ import annotations

from pathlib import Path

HERE = Path(__file__).resolve().parent
OUT = HERE / "data" / "biolector_yeast.csv"
STRAIN = "Yeast_strain_1"
KEEP_EVERY = 1  # keep every measurement cycle (3: every third, about 18 min)


def fmt(v: float, digits: int = 6) -> str:
    s = f"{v:.{digits}g}"
    return "0" if s in ("0", "-0") else s


def main():
    from pseudobatch.datasets import load_real_world_yeast_fedbatch

    df = load_real_world_yeast_fedbatch()
    df = df[df["Strain"] == STRAIN]
    lines = ["experiment,t [h],F [uL/h],F_smp [uL/h],V [uL],X [-],DO [%]"]
    for well in sorted(df["Biolector well"].unique()):
        w = df[df["Biolector well"] == well].sort_values("Time").reset_index(drop=True)
        t = w["Time"].to_numpy(float)
        acc = w["Accum. feed [uL]"].to_numpy(float)
        smp = w["Sample volume"].to_numpy(float)
        vol = w["Volume"].to_numpy(float)
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
            out.append(smp[a:b].sum() / dt)
        feed.append(feed[-1])
        out.append(0.0)
        assert abs(sum(o * (t[b] - t[a]) for o, a, b in zip(out, keep[:-1], keep[1:])) - smp.sum()) < 1e-6
        for j, i in enumerate(keep):
            lines.append(
                ",".join(
                    [
                        well,
                        f"{t[i]:.4f}",
                        fmt(feed[j], 5),
                        fmt(out[j], 5),
                        fmt(vol[i], 7),
                        fmt(float(w["Biomass concentration [light scatter]"][i]), 4),
                        fmt(float(w["DO%"][i]), 5),
                    ]
                )
            )
        print(f"{well}: {len(keep)} rows of {n} cycles, {t[0]:.2f}-{t[-1]:.2f} h, {int((smp > 0).sum())} samples")
    OUT.parent.mkdir(parents=True, exist_ok=True)
    OUT.write_text("\n".join(lines) + "\n")
    print(f"wrote {OUT} ({len(lines) - 1} rows)")


if __name__ == "__main__":
    main()
