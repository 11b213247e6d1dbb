#!/usr/bin/env python3
"""gbc against its peers, side by side in one run: the bioreactor GB2 training epoch
(N = 1000 pairs, batch 50, 20 Adam steps) timed for gbc's graph backend, gbc's fused step,
JAX (whole epoch jit-compiled) and PyTorch eager, in interleaved rounds so that every
implementation sees the same machine load.

    python bench/compare.py --rounds 5            # from the repository root

Each round runs `gbc bench --model gb2`, peer_jax.py and peer_torch.py (with PyTorch's
default threads and with one thread) once; each reports the median epoch of its run. The
table gives, per implementation, the median over rounds of those medians and the fastest
round; the ratios use the medians. `--json FILE` keeps every number.
"""

import argparse
import json
import os
import pathlib
import statistics
import subprocess
import sys
import tempfile

HERE = pathlib.Path(__file__).resolve().parent
ROOT = HERE.parent


def run_gbc(gbc, precision, epochs):
    with tempfile.TemporaryDirectory() as directory:
        out = pathlib.Path(directory) / "bench.json"
        command = [gbc, "bench", "--model", "gb2", "--precision", precision, "--epochs",
                   str(epochs), "--no-simulation", "--json", str(out)]
        subprocess.run(command, cwd=ROOT, check=True, stdout=subprocess.DEVNULL)
        rows = json.loads(out.read_text())["training"]
    return {f"gbc-{row['engine']}": row["median_epoch_seconds"] * 1e3 for row in rows}


def run_peer(python, script, arguments):
    command = [python, str(HERE / script)] + arguments
    result = subprocess.run(command, cwd=ROOT, check=True, capture_output=True, text=True)
    return json.loads(result.stdout.strip().splitlines()[-1])


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--gbc", default=str(ROOT / "target" / "release" / "gbc"))
    parser.add_argument("--python", default=sys.executable, help="interpreter with jax and torch")
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--precision", choices=["f32", "f64"], default="f32")
    parser.add_argument("--epochs", type=int, default=50, help="timed epochs of gbc and JAX")
    parser.add_argument("--torch-epochs", type=int, default=10)
    parser.add_argument("--no-torch", action="store_true")
    parser.add_argument("--json", help="write every round's numbers here")
    args = parser.parse_args()
    rounds = []
    for index in range(args.rounds):
        numbers = run_gbc(args.gbc, args.precision, args.epochs)
        jax = run_peer(args.python, "peer_jax.py",
                       ["--epochs", str(args.epochs), "--precision", args.precision])
        numbers["jax-jit"] = jax["median_ms_per_epoch"]
        if not args.no_torch:
            for threads, label in [(0, "torch-eager"), (1, "torch-eager-1-thread")]:
                torch = run_peer(args.python, "peer_torch.py",
                                 ["--epochs", str(args.torch_epochs), "--precision",
                                  args.precision, "--threads", str(threads)])
                numbers[label] = torch["median_ms_per_epoch"]
        rounds.append(numbers)
        print(f"round {index + 1}: " + ", ".join(f"{k} {v:.2f}" for k, v in numbers.items()),
              file=sys.stderr)
    names = list(rounds[0])
    median = {name: statistics.median(r[name] for r in rounds) for name in names}
    fastest = {name: min(r[name] for r in rounds) for name in names}
    print(f"bioreactor GB2, N = 1000, batch 50, {args.precision}, {args.rounds} interleaved rounds"
          f" (load average at the end: {os.getloadavg()[0]:.1f})")
    print(f"{'implementation':<22} {'median ms/epoch':>16} {'fastest round':>14} {'vs JAX':>8}")
    for name in names:
        print(f"{name:<22} {median[name]:>16.2f} {fastest[name]:>14.2f}"
              f" {median[name] / median['jax-jit']:>8.2f}")
    torch_names = [n for n in names if n.startswith("torch")]
    if torch_names:
        best_torch = min(median[n] for n in torch_names)
        for name in ["gbc-graph", "gbc-fused"]:
            if name in median:
                print(f"PyTorch eager (best of its thread settings) / {name}:"
                      f" {best_torch / median[name]:.1f}x")
    if args.json:
        pathlib.Path(args.json).write_text(json.dumps(
            {"rounds": rounds, "median": median, "fastest": fastest}, indent=2))


if __name__ == "__main__":
    main()
