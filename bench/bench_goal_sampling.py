"""Goal selection cost per episode (option ``goal_sampling``) at 1k, 10k and 100k reached
outcomes, against the bound of 1 ms per episode.

For each size and dimension, a ``GoalSampler`` (explore/learner/goal_sampling.py) of one module
learns that many outcomes (a 2-D manifold of the module's space: a fixed random map
tanh(u A + b) of points u uniform in [-1, 1]^2, plus 0.01 noise, as a ball's features or codes
are), then ``goal`` is timed, each call with its own generator as an episode's: "density"
(candidates, reference subsample, kernel density, argmin), "frontier" (the same, and the
step) and "sparse" (its 10 uniform draws included). A first, unprinted row warms the process
up. The peer is the uniform draw in the bounds (what "uniform" costs). Prints the median and
99th percentile of a choice (process CPU time, microseconds), and the slowest median's ratio
to the bound; and the cost of learning one outcome (amortised).

Dimensions: 3 (the twin's wrap-safe ball features), 2 (one MGE module of Arm-2-Balls or a
spatial autoencoder's feature), 10 (a VAE's latent means, RGE).

    .venv/bin/python bench/bench_goal_sampling.py [--sizes 1000 10000 100000] [--calls 500]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from explore.learner.goal_sampling import N_DRAWS, GoalSampler

BOUND_MS = 1.0  # the bound: goal selection under 1 ms per episode at 100k episodes


def outcomes(n: int, dim: int, seed: int = 0) -> np.ndarray:
    """(n, dim) points on a smooth 2-D manifold of [-1, 1]^dim, plus 0.01 noise."""
    rng = np.random.default_rng(seed)
    a, b = rng.normal(size=(2, dim)), rng.normal(size=dim) * 0.3
    return np.tanh(rng.uniform(-1, 1, (n, 2)) @ a + b) + rng.normal(0, 0.01, (n, dim))


def cpu_us(call, calls: int) -> np.ndarray:
    """Process CPU time of each of ``calls`` calls of ``call(k)``, microseconds."""
    out = np.empty(calls)
    for k in range(calls):
        t = time.process_time_ns()
        call(k)
        out[k] = (time.process_time_ns() - t) / 1e3
    return out


def choose(s: GoalSampler, k: int, lo: np.ndarray, hi: np.ndarray) -> np.ndarray | None:
    """One goal choice with episode ``k``'s generator ("sparse": its uniform draws too)."""
    rng = np.random.default_rng([7, k])
    if s.mode != "sparse":
        return s.goal(0, rng, lo, hi)
    drawn = np.stack([rng.uniform(lo, hi) for _ in range(N_DRAWS)])
    return s.goal(0, rng, lo, hi, drawn=drawn)


def measure(dim: int, n: int, calls: int) -> str:
    """One table row: ``n`` outcomes in ``dim`` dimensions."""
    pts = outcomes(n, dim)
    lo, hi = pts.min(0), pts.max(0)
    times = []
    for mode in ("density", "frontier", "sparse"):
        s = GoalSampler(mode, [dim])
        t = time.process_time_ns()
        for p in pts:
            s.learn([p], -1, None, lo, hi)
        learn_us = (time.process_time_ns() - t) / 1e3 / n
        times.append(cpu_us(lambda k, s=s: choose(s, k, lo, hi), calls))
    uni = cpu_us(lambda k: np.random.default_rng([7, k]).uniform(lo, hi), calls)
    cells = [f"{np.median(x):.0f}, {np.percentile(x, 99):.0f}" for x in (uni, *times)]
    ratio = max(np.median(x) for x in times) / 1e3 / BOUND_MS
    return f"| {dim} | {n} | {learn_us:.1f} | " + " | ".join(cells) + f" | {ratio:.2f} |"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[1000, 10000, 100000])
    ap.add_argument("--dims", type=int, nargs="+", default=[3, 2, 10])
    ap.add_argument("--calls", type=int, default=500)
    args = ap.parse_args()
    print(f"bound: {BOUND_MS} ms per episode; CPU microseconds per choice (median, p99)")
    print(
        "| dim | outcomes | learn one | uniform | density | frontier | sparse | slowest / bound |"
    )
    print("|---|---|---|---|---|---|---|---|")
    measure(args.dims[0], 1000, args.calls)  # warm-up: the first row alone ran 3x slower
    for dim in args.dims:
        for n in args.sizes:
            print(measure(dim, n, args.calls), flush=True)


if __name__ == "__main__":
    main()
