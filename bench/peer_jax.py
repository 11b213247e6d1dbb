#!/usr/bin/env python3
"""The bioreactor GB2 training epoch in JAX, the whole epoch jit-compiled (lax.scan over its
Adam steps): the peer gbc is measured against (issue 8, docs/performance.md).

Same problem as `gbc bench` (see gb2_pairs.py): N = 1000 pairs, batch 50, one RK4 step per
pair with the closure network evaluated at the four stages on the delay embedding (stage
estimate in its lag-0 state entries), multiplicative priors of eq. (14), physics of eq. (13),
yields through softplus, normalised MSE, Adam (lr 1e-3). Prints one JSON line.

    python bench/peer_jax.py --epochs 50 --precision f32
"""

import argparse
import json
import time

import numpy as np

import gb2_pairs


def build(problem, dtype):
    import jax
    import jax.numpy as jnp

    inverse_std = jnp.asarray(1.0 / problem.state_std, dtype)
    embeddings = jnp.asarray(problem.embeddings, dtype)
    states = jnp.asarray(problem.states, dtype)
    targets = jnp.asarray(problem.targets, dtype)
    h = problem.step

    def network(layers, inputs):
        hidden = inputs
        for weight, bias in layers[:-1]:
            hidden = jax.nn.softplus(hidden @ weight + bias)
        weight, bias = layers[-1]
        return hidden @ weight + bias

    def balances(params, x, constant):
        layers, raw_yields = params
        embedded = constant.at[:, 0:4].add(x * inverse_std)
        n = network(layers, embedded)
        X, A, B, S = x[:, 0], x[:, 1], x[:, 2], x[:, 3]
        p1 = 0.18 * jnp.exp(-A / 7 - B / 7) * S / (1 + B)
        p2 = 0.9 * jnp.exp(-A / 10) * S / (1.5 + S)
        p3 = 0.25 * jnp.exp(-A / 10) * S / (1.5 + S)
        mu, mu_a, mu_b = p1 * (1 + n[:, 0]), p2 * (1 + n[:, 1]), p3 * (1 + n[:, 2])
        y = jax.nn.softplus(raw_yields)
        d, s0 = gb2_pairs.D, gb2_pairs.S0
        return jnp.stack(
            [
                (mu - d) * X,
                mu_a * X - d * A,
                mu_b * X - d * B,
                (s0 - S) * d - (mu / y[0] + mu_a / y[1] + mu_b / y[2]) * X,
            ],
            axis=1,
        )

    def loss(params, index):
        x = states[index]
        c0, c1, c2 = embeddings[0, index], embeddings[1, index], embeddings[2, index]
        k1 = balances(params, x, c0)
        k2 = balances(params, x + h / 2 * k1, c1)
        k3 = balances(params, x + h / 2 * k2, c1)
        k4 = balances(params, x + h * k3, c2)
        following = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        residual = (following - targets[index]) * inverse_std
        return jnp.mean(residual * residual)

    beta1, beta2, epsilon, rate = 0.9, 0.999, 1e-8, 1e-3

    def adam_step(carry, index):
        params, first, second, count = carry
        value, grads = jax.value_and_grad(loss)(params, index)
        count = count + 1
        first = jax.tree_util.tree_map(lambda m, g: beta1 * m + (1 - beta1) * g, first, grads)
        second = jax.tree_util.tree_map(lambda v, g: beta2 * v + (1 - beta2) * g * g, second, grads)
        c1 = 1 - beta1**count
        c2 = 1 - beta2**count
        params = jax.tree_util.tree_map(
            lambda p, m, v: p - rate * (m / c1) / (jnp.sqrt(v / c2) + epsilon),
            params,
            first,
            second,
        )
        return (params, first, second, count), value

    @jax.jit
    def epoch(carry, order):
        return jax.lax.scan(adam_step, carry, order)

    layers = [(jnp.asarray(w, dtype), jnp.asarray(b, dtype)) for w, b in problem.weights]
    params = (layers, jnp.asarray(problem.raw_yields, dtype))
    zeros = jax.tree_util.tree_map(jnp.zeros_like, params)
    carry = (params, zeros, zeros, jnp.asarray(0.0, dtype))
    return epoch, carry


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", default=str(gb2_pairs.DEFAULT_DATA))
    parser.add_argument("--train-points", type=int, default=1000)
    parser.add_argument("--batch", type=int, default=50)
    parser.add_argument("--epochs", type=int, default=50, help="timed epochs")
    parser.add_argument("--precision", choices=["f32", "f64"], default="f32")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    if args.precision == "f64":
        import jax

        jax.config.update("jax_enable_x64", True)
    import jax
    import jax.numpy as jnp

    problem = gb2_pairs.Problem(args.data, args.train_points, args.seed)
    dtype = jnp.float32 if args.precision == "f32" else jnp.float64
    epoch, carry = build(problem, dtype)
    steps = args.train_points // args.batch
    rng = np.random.default_rng(args.seed)

    def order():
        permutation = rng.permutation(args.train_points)[: steps * args.batch]
        return jnp.asarray(permutation.reshape(steps, args.batch))

    carry, losses = epoch(carry, order())  # compiles
    jax.block_until_ready(losses)
    times = []
    for _ in range(args.epochs):
        started = time.perf_counter()
        carry, losses = epoch(carry, order())
        jax.block_until_ready(losses)
        times.append(time.perf_counter() - started)
    extra = {
        "precision": args.precision,
        "jax": jax.__version__,
        "final_loss": float(losses[-1]),
    }
    print(json.dumps(gb2_pairs.summary("jax-jit", times, steps, extra)))


if __name__ == "__main__":
    main()
