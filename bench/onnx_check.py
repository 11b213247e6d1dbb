#!/usr/bin/env python3
"""Check an exported model with onnxruntime against gbc's own online prediction.

Exports the trained run with `gbc export`, predicts the record online with `gbc predict
--mode online-trained-step`, then steps the ONNX file over the same free run with onnxruntime (window
from the record before the start, the model's own predictions after it) and reports the
largest relative error of the states and closure outputs (relative to each column's
largest magnitude).

    python3 bench/onnx_check.py MODEL RUN_DIR DATA.csv [--gbc target/release/gbc]

Needs `pip install onnxruntime numpy` (optional; CI does not run it). Exit code 1 when the
error exceeds --tolerance (default 1e-5, the f32 bound gbc's own test asserts with tract).
"""

import argparse
import csv
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import onnxruntime as ort


def read_csv(path):
    with open(path, newline="") as handle:
        rows = list(csv.reader(handle))
    header = rows[0]
    columns = {name: np.array([float(r[i]) if r[i] else np.nan for r in rows[1:]])
               for i, name in enumerate(header)}
    return header, columns


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("model")
    parser.add_argument("weights")
    parser.add_argument("data")
    parser.add_argument("--gbc", default="target/release/gbc")
    parser.add_argument("--tolerance", type=float, default=1e-5)
    args = parser.parse_args()

    work = Path(tempfile.mkdtemp(prefix="gbc-onnx-"))
    onnx_path, predicted_path = work / "model.onnx", work / "online.csv"
    subprocess.run([args.gbc, "export", args.model, "--weights", args.weights,
                    "-o", str(onnx_path)], check=True)
    subprocess.run([args.gbc, "predict", args.model, args.data, "--weights", args.weights,
                    "--mode", "online-trained-step", "-o", str(predicted_path)], check=True)

    session = ort.InferenceSession(str(onnx_path))
    meta = session.get_modelmeta().custom_metadata_map
    window = int(meta["gbc.window"])
    states = meta["gbc.states"].split(",")
    inputs = [n for n in meta["gbc.inputs"].split(",") if n]
    closure_outputs = [n for n in meta["gbc.closure_outputs"].split(",") if n]
    hidden_names = [n for n in meta["gbc.hidden"].split(",") if n]
    hidden_initial = [float(v) for v in meta["gbc.hidden_initial"].split(",") if v]

    _, data = read_csv(args.data)
    _, online = read_csv(predicted_path)
    times = data["t"]
    start = int(np.argmin(np.abs(times - online["t"][0])))
    steps = len(online["t"]) - 1

    def rows(names, knots):
        knots = np.clip(knots, 0, len(times) - 1)
        return np.stack([data[n][knots] for n in names], axis=1).astype(np.float32)

    names = ["next_state"] + (["closure_outputs"] if closure_outputs else [])
    names += ["next_hidden"] if hidden_names else []

    def call(state_window, knot, hidden):
        feed = {"state_window": state_window[None]}
        if inputs:
            feed["input_window"] = rows(inputs, np.arange(knot - window + 1, knot + 1))[None]
        if hidden_names:
            feed["hidden"] = hidden[None]
        return dict(zip(names, (r[0] for r in session.run(names, feed))))

    # Hidden states run in along the data from the first row (measured states reset to
    # the data), as gbc does before a free run.
    hidden = np.array(hidden_initial, dtype=np.float32)
    for knot in range(start if hidden_names else 0):
        hidden = call(rows(states, np.arange(knot - window + 1, knot + 1)), knot, hidden)["next_hidden"]
    state_window = rows(states, np.arange(start - window + 1, start + 1))
    found_states, found_closures = [], []
    for step in range(steps):
        result = call(state_window, start + step, hidden)
        found_states.append(result["next_state"])
        if closure_outputs:
            found_closures.append(result["closure_outputs"])
        if hidden_names:
            hidden = result["next_hidden"]
        state_window = np.vstack([state_window[1:], result["next_state"][None]])

    def worst(found, names, skip):
        expected = np.stack([online[n][skip:skip + len(found)] for n in names], axis=1)
        scale = np.abs(expected).max(axis=0)
        return float((np.abs(np.array(found) - expected) / scale).max())

    error = worst(found_states, states, 1)
    if closure_outputs:
        error = max(error, worst(found_closures, closure_outputs, 0))
    print(f"{args.model}: {steps} steps, largest relative error {error:.3e} "
          f"(onnxruntime {ort.__version__})")
    return 0 if error < args.tolerance else 1


if __name__ == "__main__":
    sys.exit(main())
