#!/usr/bin/env python3
"""Write data/pensim.csv: ten industrial penicillin fed-batches from pensimpy (IndPenSim).

The only writer of data/pensim.csv (no hand edits). Steps (SOURCE.md says why):

    python3 -m venv .venv && . .venv/bin/activate
    pip install numpy==2.4.6 scipy==1.17.1 pandas==3.1.1   # the versions that wrote the CSV
    python convert.py [CACHE]    # 2-9 minutes (14-26 s of CPU a batch)

1. `python3 -m pip download --no-deps pensimpy==1.2.5 -d CACHE` (this script runs it through
   `registry.fetch`; CACHE defaults to /tmp/gbc-corpus-cache, or pass a folder with the
   wheel already in it as the first argument), and check the wheel's sha256;
2. import pensimpy from that checked wheel (a pure-Python wheel is a zip: it is put first on
   sys.path and imported through zipimport; nothing is installed);
3. simulate and write the columns below.

pensimpy 1.2.5 pins numpy==1.18.2, pandas==1.0.3 and scipy==1.4.1 (none builds on a current
Python) and imports `fastodeint`, a C++ solver that is not on PyPI. So it is used without its
pins (with the venv's numpy, scipy, pandas), and its own pure-Python path is used:
PenSimEnv(fast=False) integrates the package's `indpensim_ode_py` with scipy's odeint.
`fastodeint` is imported at the top of `pensimpy.peni_env_setup` but only called when
fast=True: an empty stand-in module lets the import succeed, and calling it would fail loudly.

What is simulated: ten batches of 230 h (the package's fixed length), each with its own
random seed (initial conditions, the package's process disturbances on growth, production,
feed concentrations, coolant and inlet oxygen) and its own recipe: the package's default
sequential-batch-control recipe with each feed profile scaled by a factor drawn from a
seeded generator (sugar, oil, aeration, water, discharge), within +-15 %.

Recipe convention: IndPenSim's recipe table gives each value *up to* the time listed (the
original MATLAB code: `if k <= 15, Fs = 8; elseif k <= 60, Fs = 15; ...` with 0.2 h steps).
pensimpy 1.2.5's `Recipe.get_value_at` reads the table the other way round (each value
*from* its time on), which discharges broth at 4000 L/h from 102 h to 130 h and empties the
tank (the run then fails at about 137 h). This script reads the recipe the IndPenSim way.

What is written, as a plant historian would give it (one row per 0.4 h, plus a row per
off-line sample that falls between them):
- on-line every 0.4 h: the flows set by the recipe and the controllers, as 0.4 h means
  time-stamped at the start of their interval (so that holding each value until the next
  row delivers exactly the volume the simulator received); the broth volume, dissolved
  oxygen and off-gas CO2 read at the row's time;
- off-line about every 12 h (12 h apart, jittered by up to 1.6 h, on the simulator's 0.2 h
  grid), plus one sample at inoculation: biomass, residual sugar and penicillin.
pensimpy adds no measurement noise to these channels (only to its Raman spectra, which are
not written): the values are the simulator's, rounded to 4 significant digits.
"""

from __future__ import annotations

import math
import os
import sys
import time
import types
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
import registry  # noqa: E402  (bench/corpus/real/registry.py)

PACKAGE = "pensimpy"
VERSION = "1.2.5"
ARCHIVE = f"{PACKAGE}-{VERSION}-py3-none-any.whl"
SHA256 = "6fb361876b5392ecbd1ec8f855f1c1c4772de6667d1dc16d85bde8f8be498644"

HERE = Path(__file__).resolve().parent
OUT = HERE / "data" / "pensim.csv"

N_BATCHES = 10
STEP_H = 0.2  # pensimpy's control and record step
ROW_STEPS = 2  # one on-line row every 2 steps = 0.4 h
OFFLINE_EVERY_H = 12.0
OFFLINE_JITTER_STEPS = 8  # +-1.6 h
RECIPE_SEED = 20240611


def fetch(cache):
    """The package's wheel in `cache`, checked (`registry.fetch`)."""
    return registry.fetch(cache, PACKAGE, VERSION, ARCHIVE, SHA256)


def _import_pensimpy(wheel):
    """pensimpy's classes, imported from the checked wheel `wheel` (pure Python: zipimport)."""
    sys.path.insert(0, wheel)
    stub = types.ModuleType("fastodeint")

    def _refuse(*_args, **_kwargs):
        raise RuntimeError("fastodeint is a stand-in: use PenSimEnv(fast=False)")

    stub.integrate = _refuse
    sys.modules.setdefault("fastodeint", stub)
    from pensimpy.peni_env_setup import PenSimEnv
    from pensimpy.data import constants as C
    from pensimpy.constants import NUM_STEPS

    import pensimpy

    if not os.path.abspath(pensimpy.__file__).startswith(os.path.abspath(wheel) + os.sep):
        sys.exit(f"pensimpy imported from {pensimpy.__file__}, not from the checked {wheel}")
    return PenSimEnv, C, NUM_STEPS


def value_until(profile, t):
    """IndPenSim's reading of a recipe table: the value of the first entry whose time is
    at or after t (the last value after the table's end)."""
    for sp in profile:
        if t <= sp["time"] + 1e-9:
            return sp["value"]
    return profile[-1]["value"]


def scaled(profile, factor):
    return [{"time": sp["time"], "value": sp["value"] * factor} for sp in profile]


def run_batch(PenSimEnv, C, num_steps, batch):
    """Simulate batch `batch` (1-based); return the per-step arrays."""
    rng = np.random.RandomState(RECIPE_SEED + batch)
    factors = {
        "Fs": rng.uniform(0.85, 1.15),
        "Foil": rng.uniform(0.85, 1.15),
        "Fg": rng.uniform(0.90, 1.10),
        "Fw": rng.uniform(0.85, 1.15),
        "discharge": rng.uniform(0.90, 1.10),
    }
    recipe = {
        "Fs": scaled(C.FS_DEFAULT_PROFILE, factors["Fs"]),
        "Foil": scaled(C.FOIL_DEFAULT_PROFILE, factors["Foil"]),
        "Fg": scaled(C.FG_DEFAULT_PROFILE, factors["Fg"]),
        "pressure": C.PRESS_DEFAULT_PROFILE,
        "discharge": scaled(C.DISCHARGE_DEFAULT_PROFILE, factors["discharge"]),
        "Fw": scaled(C.WATER_DEFAULT_PROFILE, factors["Fw"]),
        "Fpaa": C.PAA_DEFAULT_PROFILE,
    }
    # Raman noise draws from numpy's global generator: seed it so reruns are identical.
    np.random.seed(1000 + batch)
    env = PenSimEnv(recipe_combo=None, fast=False)
    env.random_seed_ref = batch
    _, x = env.reset()
    x0 = env.x0
    for k in range(1, num_steps + 1):
        t = k * STEP_H
        v = {name: value_until(prof, t) for name, prof in recipe.items()}
        _, x, _, _ = env.step(
            k, x, v["Fs"], v["Foil"], v["Fg"], v["pressure"], v["discharge"], v["Fw"], v["Fpaa"]
        )
    # States after step k are stored at index k-1; the initial state comes from x0.
    states = {
        "X": [x0.X] + list(x.X.y),
        "S": [x0.S] + list(x.S.y),
        "P": [x0.P] + list(x.P.y),
        "V": [x0.V] + list(x.V.y),
        "DO2": [x0.DO2] + list(x.DO2.y),
        "CO2": [x0.CO2outgas] + list(x.CO2outgas.y),
    }
    # Flows of step k act on ((k-1) h, k h]; discharge is stored negative (an outflow).
    flows = {
        "F_s": list(x.Fs.y),
        "F_oil": list(x.Foil.y),
        "F_w": list(x.Fw.y),
        "F_ab": [a + b for a, b in zip(x.Fa.y, x.Fb.y)],
        "F_paa": list(x.Fpaa.y),
        "F_dis": [-d for d in x.discharge.y],
    }
    return states, flows, factors


def sig(v, digits=4):
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return ""
    if v == 0:
        return "0"
    return f"{v:.{digits}g}"


def main():
    cache = sys.argv[1] if len(sys.argv) > 1 else "/tmp/gbc-corpus-cache"
    wheel = fetch(cache)
    warnings.simplefilter("ignore")
    PenSimEnv, C, num_steps = _import_pensimpy(wheel)
    flow_cols = ["F_s", "F_oil", "F_w", "F_ab", "F_paa", "F_dis"]
    header = (
        ["experiment", "t [h]"]
        + [f"{c} [L/h]" for c in flow_cols]
        + ["DO2 [mg/L]", "CO2 [%]", "V [L]", "X [g/L]", "S [g/L]", "P [g/L]"]
    )
    lines = [",".join(header)]
    summary = []
    t0 = time.time()
    for b in range(1, N_BATCHES + 1):
        name = f"B{b}"
        states, flows, factors = run_batch(PenSimEnv, C, num_steps, b)
        # Off-line sampling steps: inoculation, then every 12 h with jitter.
        rng = np.random.RandomState(7000 + b)
        per = int(round(OFFLINE_EVERY_H / STEP_H))
        offline = {0}
        for i in range(1, int(num_steps // per) + 1):
            k = i * per + rng.randint(-OFFLINE_JITTER_STEPS, OFFLINE_JITTER_STEPS + 1)
            if 0 < k <= num_steps:
                offline.add(k)
        online = set(range(0, num_steps + 1, ROW_STEPS))
        n_rows = 0
        for k in sorted(online | offline):
            row = [name, f"{k * STEP_H:.1f}"]
            if k in online and k + ROW_STEPS <= num_steps:
                for c in flow_cols:
                    row.append(sig(float(np.mean(flows[c][k : k + ROW_STEPS]))))
            elif k in online:
                # The last row: the flows of the last step (nothing follows it).
                for c in flow_cols:
                    row.append(sig(flows[c][k - 1]))
            else:
                row += [""] * len(flow_cols)
            if k in online:
                row += [sig(states["DO2"][k]), sig(states["CO2"][k]), f"{states['V'][k]:.0f}"]
            else:
                row += ["", "", ""]
            if k in offline:
                row += [sig(states["X"][k]), sig(states["S"][k]), sig(states["P"][k])]
            else:
                row += ["", "", ""]
            lines.append(",".join(row))
            n_rows += 1
        summary.append(
            f"{name}: {n_rows} rows, {len(offline)} off-line samples, final P "
            f"{states['P'][-1]:.2f} g/L, X {states['X'][-1]:.1f} g/L, V {states['V'][-1]:.0f} L; "
            + ", ".join(f"{k} x{v:.3f}" for k, v in factors.items())
        )
        print(summary[-1], f"({time.time() - t0:.0f} s)", flush=True)
    OUT.parent.mkdir(parents=True, exist_ok=True)
    OUT.write_text("\n".join(lines) + "\n")
    print(f"wrote {OUT} ({len(lines) - 1} rows)")


if __name__ == "__main__":
    main()
