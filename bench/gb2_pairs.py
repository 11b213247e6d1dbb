"""The bioreactor GB2 training problem of gbc, rebuilt in NumPy for the peer benchmarks.

Everything here mirrors what `gbc train models/bioreactor/gb2.gbm
models/bioreactor/data/steps.csv --train-points 1000 --batch 50` does before its first Adam
step (src/train/pairs.rs, src/train/mod.rs, src/backend/net.rs), so that peer_jax.py and
peer_torch.py time the same computation:

- the record's columns u, X, A, B, S; pairs start at row 45 (the embedding spans 9 x 5 h);
- normalisation: mean and population std of every column over the rows the training pairs
  cover (the first 45 + N + 1 rows);
- the delay embedding of (X, A, B, S, u), delay 5 h, dimension 10, lag-major, at the RK4
  stage times t, t + h/2, t + h: states interpolated linearly, the input held (its left
  limit at t + h); lag-0 state columns hold -mean/std, the stage estimate x/std is added
  inside the step;
- weights: Glorot-uniform, the last layer scaled by 1e-2, zero biases, raw yields at the
  inverse softplus of 0.5 (the declared initial guesses).

This file is a benchmark tool, not part of gbc's tests.
"""

import csv
import math
import pathlib

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parent.parent
DEFAULT_DATA = ROOT / "models" / "bioreactor" / "data" / "steps.csv"

STATES = ["X", "A", "B", "S"]
INPUT = "u"
OBSERVED = ["X", "A", "B", "S", "u"]
DELAY = 5.0
DIM = 10
WIDTHS = [50, 20, 20, 20, 3]
D = 0.05
S0 = 20.0
INITIAL_YIELD = 0.5
INIT_LAST_LAYER = 1e-2
FRACTIONS = [0.0, 0.5, 1.0]


def read_record(path):
    """Columns of the CSV as float arrays, and the sampling step."""
    with open(path, newline="") as handle:
        rows = list(csv.reader(handle))
    header, body = rows[0], rows[1:]
    columns = {name: np.array([float(r[i]) for r in body]) for i, name in enumerate(header)}
    times = columns["t"]
    step = float((times[-1] - times[0]) / (len(times) - 1))
    return columns, step


def interpolate(values, position):
    """Linear interpolation at a fractional sample position (clamped to the record)."""
    nearest = round(position)
    if abs(position - nearest) < 1e-9:
        position = float(nearest)
    last = len(values) - 1
    position = min(max(position, 0.0), float(last))
    below = int(math.floor(position))
    fraction = position - below
    if fraction == 0.0 or below >= last:
        return values[min(below, last)]
    return values[below] * (1.0 - fraction) + values[below + 1] * fraction


def hold(values, position, left_limit):
    """Zero-order hold: the sample at or before the position (strictly before with
    left_limit when the position falls on a sample)."""
    nearest = round(position)
    if abs(position - nearest) < 1e-9:
        position = float(nearest)
    index = math.ceil(position) - 1 if left_limit else math.floor(position)
    return values[min(max(index, 0), len(values) - 1)]


class Problem:
    """Normalised pair table and initial weights of the GB2 benchmark, as NumPy arrays."""

    def __init__(self, data_path=DEFAULT_DATA, train_points=1000, seed=0):
        columns, step = read_record(data_path)
        self.step = step
        first = math.ceil((DIM - 1) * DELAY / step - 1e-9)
        covered = first + train_points + 1
        stats = {}
        for name in OBSERVED:
            values = columns[name][:covered]
            mean = values.mean()
            std = values.std()
            stats[name] = (mean, std if std > 1e-12 * max(abs(mean), 1e-300) else 1.0)
        self.state_std = np.array([stats[s][1] for s in STATES])
        rows = range(first, first + train_points)
        self.states = np.array([[columns[s][r] for s in STATES] for r in rows])
        self.inputs = np.array([[columns[INPUT][r]] for r in rows])
        self.targets = np.array([[columns[s][r + 1] for s in STATES] for r in rows])
        lag_in_samples = DELAY / step
        self.embeddings = np.zeros((len(FRACTIONS), train_points, DIM * len(OBSERVED)))
        for offset, fraction in enumerate(FRACTIONS):
            for pair, row in enumerate(rows):
                for lag in range(DIM):
                    position = row + fraction - lag * lag_in_samples
                    for k, name in enumerate(OBSERVED):
                        mean, std = stats[name]
                        if name == INPUT:
                            raw = hold(columns[name], position, fraction >= 1.0)
                        elif lag == 0:
                            raw = 0.0
                        else:
                            raw = interpolate(columns[name], position)
                        self.embeddings[offset, pair, lag * len(OBSERVED) + k] = (raw - mean) / std
        self.weights = initial_weights(seed)
        self.raw_yields = np.full(3, INITIAL_YIELD + math.log(-math.expm1(-INITIAL_YIELD)))


def initial_weights(seed):
    """[(W, b)] per layer, W of shape (fan_in, fan_out) as in gbc (x @ W + b)."""
    rng = np.random.default_rng(seed)
    layers = []
    for index, (fan_in, fan_out) in enumerate(zip(WIDTHS[:-1], WIDTHS[1:])):
        limit = math.sqrt(6.0 / (fan_in + fan_out))
        if index == len(WIDTHS) - 2:
            limit *= INIT_LAST_LAYER
        layers.append((rng.uniform(-limit, limit, (fan_in, fan_out)), np.zeros(fan_out)))
    return layers


def summary(name, per_epoch_seconds, steps_per_epoch, extra=None):
    """The JSON record every peer prints: median and quartiles of the epoch times."""
    times = np.sort(np.array(per_epoch_seconds))
    record = {
        "implementation": name,
        "epochs": len(times),
        "steps_per_epoch": steps_per_epoch,
        "median_ms_per_epoch": float(np.median(times) * 1e3),
        "q1_ms_per_epoch": float(np.percentile(times, 25) * 1e3),
        "q3_ms_per_epoch": float(np.percentile(times, 75) * 1e3),
        "median_ms_per_step": float(np.median(times) * 1e3 / steps_per_epoch),
    }
    record.update(extra or {})
    return record
