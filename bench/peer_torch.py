#!/usr/bin/env python3
"""The bioreactor GB2 training epoch in PyTorch, eager mode with torch.optim.Adam: how a
researcher would usually write it (issue 8, docs/performance.md).

Same problem as `gbc bench` and peer_jax.py (see gb2_pairs.py). Prints one JSON line.

    python bench/peer_torch.py --epochs 20 --precision f32
"""

import argparse
import json
import time

import numpy as np
import torch
import torch.nn.functional as F

import gb2_pairs


class GreyBox(torch.nn.Module):
    """The closure network, the priors of eq. (14) and the balances of eq. (13)."""

    def __init__(self, problem, dtype):
        super().__init__()
        self.layers = torch.nn.ModuleList()
        for weight, bias in problem.weights:
            layer = torch.nn.Linear(weight.shape[0], weight.shape[1], dtype=dtype)
            with torch.no_grad():
                layer.weight.copy_(torch.tensor(weight.T, dtype=dtype))
                layer.bias.copy_(torch.tensor(bias, dtype=dtype))
            self.layers.append(layer)
        self.raw_yields = torch.nn.Parameter(torch.tensor(problem.raw_yields, dtype=dtype))
        self.inverse_std = torch.tensor(1.0 / problem.state_std, dtype=dtype)

    def balances(self, x, constant):
        embedded = constant.clone()
        embedded[:, 0:4] += x * self.inverse_std
        hidden = embedded
        for layer in self.layers[:-1]:
            hidden = F.softplus(layer(hidden))
        n = self.layers[-1](hidden)
        X, A, B, S = x[:, 0], x[:, 1], x[:, 2], x[:, 3]
        p1 = 0.18 * torch.exp(-A / 7 - B / 7) * S / (1 + B)
        p2 = 0.9 * torch.exp(-A / 10) * S / (1.5 + S)
        p3 = 0.25 * torch.exp(-A / 10) * S / (1.5 + S)
        mu, mu_a, mu_b = p1 * (1 + n[:, 0]), p2 * (1 + n[:, 1]), p3 * (1 + n[:, 2])
        y = F.softplus(self.raw_yields)
        d, s0 = gb2_pairs.D, gb2_pairs.S0
        return torch.stack(
            [
                (mu - d) * X,
                mu_a * X - d * A,
                mu_b * X - d * B,
                (s0 - S) * d - (mu / y[0] + mu_a / y[1] + mu_b / y[2]) * X,
            ],
            dim=1,
        )

    def forward(self, x, c0, c1, c2, h):
        k1 = self.balances(x, c0)
        k2 = self.balances(x + h / 2 * k1, c1)
        k3 = self.balances(x + h / 2 * k2, c1)
        k4 = self.balances(x + h * k3, c2)
        return x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", default=str(gb2_pairs.DEFAULT_DATA))
    parser.add_argument("--train-points", type=int, default=1000)
    parser.add_argument("--batch", type=int, default=50)
    parser.add_argument("--epochs", type=int, default=20, help="timed epochs")
    parser.add_argument("--precision", choices=["f32", "f64"], default="f32")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--threads", type=int, default=0, help="torch threads (0: default)")
    args = parser.parse_args()
    if args.threads > 0:
        torch.set_num_threads(args.threads)
    dtype = torch.float32 if args.precision == "f32" else torch.float64
    problem = gb2_pairs.Problem(args.data, args.train_points, args.seed)
    model = GreyBox(problem, dtype)
    optimiser = torch.optim.Adam(model.parameters(), lr=1e-3)
    embeddings = torch.tensor(problem.embeddings, dtype=dtype)
    states = torch.tensor(problem.states, dtype=dtype)
    targets = torch.tensor(problem.targets, dtype=dtype)
    inverse_std = model.inverse_std
    rng = np.random.default_rng(args.seed)
    steps = args.train_points // args.batch

    def epoch():
        order = torch.as_tensor(rng.permutation(args.train_points))
        value = None
        for step in range(steps):
            index = order[step * args.batch : (step + 1) * args.batch]
            x = states[index]
            following = model(x, embeddings[0, index], embeddings[1, index], embeddings[2, index], problem.step)
            residual = (following - targets[index]) * inverse_std
            value = torch.mean(residual * residual)
            optimiser.zero_grad()
            value.backward()
            optimiser.step()
        return float(value.detach())

    epoch()
    times = []
    loss = None
    for _ in range(args.epochs):
        started = time.perf_counter()
        loss = epoch()
        times.append(time.perf_counter() - started)
    extra = {
        "precision": args.precision,
        "torch": torch.__version__,
        "threads": torch.get_num_threads(),
        "final_loss": loss,
    }
    print(json.dumps(gb2_pairs.summary("torch-eager", times, steps, extra)))


if __name__ == "__main__":
    main()
