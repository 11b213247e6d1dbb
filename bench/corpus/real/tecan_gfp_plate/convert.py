#!/usr/bin/env python3
"""Write data/plate.csv from the Tecan plate-reader record shipped in curveball 0.3.0.

The only writer of data/ (no hand edits). Standard library only (the workbook is read as
the zip of XML it is). Steps:

1. `python3 -m pip download --no-deps curveball==0.3.0 -d CACHE` (this script runs it;
   CACHE defaults to /tmp/gbc-corpus-cache, or pass a folder with the wheel already in it
   as the first argument), and check the wheel's sha256;
2. read `data/Tecan_210115.xlsx` (the Infinite 200Pro export: 96 wells, 89 kinetic
   cycles of OD595, green fluorescence 485/540 nm and red fluorescence 535/620 nm) and
   `plate_templates/G-RG-R.csv` (the plate layout: which well holds the green strain G,
   the red strain R, their mixture RG, or nothing) out of the wheel;
3. keep the 8 wells of the green strain G in plate column 2 (A2 ... H2; the plate has 32
   wells of G in columns 1-4, which would make the greybox's cross-validation 4 times
   longer); one experiment per well, named by the well;
4. per cycle: t = the cycle's `Time [s]` of the OD table / 3600 [h]; OD = the OD595
   reading; GFP = the green fluorescence reading (the three tables share their cycle
   times); the red channel and the other wells are not written;
5. write the rows in time order, well by well (A2, B2, ..., H2).

Run from anywhere: `python3 convert.py [CACHE]`.
"""
import csv
import io
import os
import re
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
import registry  # noqa: E402  (bench/corpus/real/registry.py)
import zipfile
import xml.etree.ElementTree as ET

PACKAGE = "curveball"
VERSION = "0.3.0"
ARCHIVE = f"{PACKAGE}-{VERSION}-py3-none-any.whl"
SHA256 = "6f68b3c8f31470c02e086e38d4b6db6272babd7d03866595e73ec173cf6ed47a"
WORKBOOK = "data/Tecan_210115.xlsx"
TEMPLATE = "plate_templates/G-RG-R.csv"
STRAIN = "G"
COLUMN = "2"

HERE = os.path.dirname(os.path.abspath(__file__))
OUT = os.path.join(HERE, "data", "plate.csv")
NS = "{http://schemas.openxmlformats.org/spreadsheetml/2006/main}"


def fetch(cache):
    """The package's archive in `cache`, checked (`registry.fetch`)."""
    return registry.fetch(cache, PACKAGE, VERSION, ARCHIVE, SHA256)


def column_index(ref):
    letters = re.match(r"[A-Z]+", ref).group(0)
    n = 0
    for ch in letters:
        n = n * 26 + ord(ch) - ord("A") + 1
    return n - 1


def read_sheet(xlsx_bytes):
    """The first worksheet as a list of rows, each a dict column index -> str or float."""
    with zipfile.ZipFile(io.BytesIO(xlsx_bytes)) as xl:
        strings = []
        if "xl/sharedStrings.xml" in xl.namelist():
            for si in ET.fromstring(xl.read("xl/sharedStrings.xml")).iter(NS + "si"):
                strings.append("".join(t.text or "" for t in si.iter(NS + "t")))
        rows = []
        for row in ET.fromstring(xl.read("xl/worksheets/sheet1.xml")).iter(NS + "row"):
            cells = {}
            for c in row.iter(NS + "c"):
                v = c.find(NS + "v")
                if v is None or v.text is None:
                    continue
                kind = c.get("t")
                if kind == "s":
                    cells[column_index(c.get("r"))] = strings[int(v.text)]
                elif kind in ("str", "inlineStr"):
                    cells[column_index(c.get("r"))] = v.text
                else:
                    cells[column_index(c.get("r"))] = float(v.text)
            rows.append((int(row.get("r")), cells))
    return rows


def table(rows, label):
    """The kinetic table under the row whose first cell is `label`: times [s] and well -> readings."""
    start = next(i for i, (_, c) in enumerate(rows) if c.get(0) == label)
    data = {}
    for _, cells in rows[start + 1:]:
        name = cells.get(0)
        if not isinstance(name, str) or not name:
            break
        data[name] = [cells[k] for k in sorted(cells) if k > 0 and isinstance(cells[k], float)]
    return data["Time [s]"], data


def main():
    cache = sys.argv[1] if len(sys.argv) > 1 else "/tmp/gbc-corpus-cache"
    with zipfile.ZipFile(fetch(cache)) as whl:
        rows = read_sheet(whl.read(WORKBOOK))
        layout = list(csv.DictReader(io.StringIO(whl.read(TEMPLATE).decode("utf-8"))))
    wells = [f"{r['Row']}{r['Col']}" for r in layout if r["Strain"] == STRAIN and r["Col"] == COLUMN]
    wells.sort(key=lambda w: (int(w[1:]), w[0]))
    t_od, od = table(rows, "OD")
    t_gfp, gfp = table(rows, "Green")
    out = []
    for well in wells:
        for i, ts in enumerate(t_od):
            if i < len(t_gfp) and abs(t_gfp[i] - ts) > 1.0:
                sys.exit(f"cycle {i + 1}: OD at {ts} s, green at {t_gfp[i]} s")
            g = gfp[well][i] if i < len(gfp[well]) else None
            out.append([well, f"{ts / 3600:.5f}", f"{od[well][i]:.4f}", "" if g is None else f"{g:.0f}"])
    os.makedirs(os.path.dirname(OUT), exist_ok=True)
    with open(OUT, "w", newline="") as f:
        wr = csv.writer(f, lineterminator="\n")
        wr.writerow(["experiment", "t [h]", "OD [-]", "GFP [a.u.]"])
        wr.writerows(out)
    print(f"wrote {OUT}: {len(wells)} experiments, {len(out)} rows")


if __name__ == "__main__":
    main()
