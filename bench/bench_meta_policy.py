"""Meta-policy query time as the history grows: 1k, 10k and 100k stored episodes.

Issue 6's benchmark. For each size, a ``MetaPolicy`` with one module is filled with random
episodes (context and outcome uniform in [-1, 1], 48 parameters), then timed on random
queries (``infer``: nearest neighbour plus exploration noise, sigma 0.05). The peer, in the
same run on the same points, is a brute-force scan (numpy distance to every point, argmin),
which is what a query costs without the tree. Two shapes: the engineered goal space (context 3
+ outcome 3) and a VAE's (context 10 + outcome 10).

Prints per size: the insertion cost per episode (amortised over the tree rebuilds), the
points left outside the tree (scanned by brute force until the next rebuild), the median and
99th percentile of a query, the brute-force median and the speed-up over it.

    .venv/bin/python bench/bench_meta_policy.py [--sizes 1000 10000 100000] [--queries 2000]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from explore.dmp import N_PARAMS
from explore.meta_policy import MetaPolicy

SHAPES = {"engineered (3 + 3)": (3, 3), "VAE latents (10 + 10)": (10, 10)}


def fill(policy: MetaPolicy, n: int, rng: np.random.Generator) -> float:
    """Add ``n`` random episodes; returns the mean seconds per ``add``."""
    c_dim, o_dim = policy.context_dim, policy.module_dims[0]
    contexts = rng.uniform(-1, 1, (n, c_dim))
    outcomes = rng.uniform(-1, 1, (n, o_dim))
    thetas = rng.uniform(-1, 1, (n, N_PARAMS))
    t0 = time.perf_counter()
    for i in range(n):
        policy.add(contexts[i], [outcomes[i]], thetas[i])
    return (time.perf_counter() - t0) / n


def time_queries(policy: MetaPolicy, queries: int, rng: np.random.Generator) -> np.ndarray:
    """Seconds of each of ``queries`` random ``infer`` calls."""
    c_dim, o_dim = policy.context_dim, policy.module_dims[0]
    out = np.empty(queries)
    for k in range(queries):
        c, g = rng.uniform(-1, 1, c_dim), rng.uniform(-1, 1, o_dim)
        t0 = time.perf_counter()
        policy.infer(0, c, g, rng, 0.05)
        out[k] = time.perf_counter() - t0
    return out


def time_brute(points: np.ndarray, queries: int, rng: np.random.Generator) -> np.ndarray:
    """Seconds of each of ``queries`` brute-force nearest-neighbour scans over ``points``."""
    out = np.empty(queries)
    for k in range(queries):
        q = rng.uniform(-1, 1, points.shape[1])
        t0 = time.perf_counter()
        int(np.argmin(np.linalg.norm(points - q, axis=1)))
        out[k] = time.perf_counter() - t0
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[1000, 10000, 100000])
    ap.add_argument("--queries", type=int, default=2000)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    rng = np.random.default_rng(args.seed)
    for label, (c_dim, o_dim) in SHAPES.items():
        print(f"\n{label}")
        print("  episodes  add_us  outside_tree  query_us_median  query_us_p99  "
              "brute_us_median  speed-up")  # fmt: skip
        for n in args.sizes:
            policy = MetaPolicy(c_dim, [o_dim], N_PARAMS)
            add_s = fill(policy, n, rng)
            index = policy.indexes[0]
            q = time_queries(policy, args.queries, rng) * 1e6
            b = time_brute(index.points, args.queries, rng) * 1e6
            outside = len(index) - index._n_tree
            print(f"  {n:8d}  {add_s * 1e6:6.1f}  {outside:12d}  {np.median(q):15.1f}  "
                  f"{np.percentile(q, 99):12.1f}  {np.median(b):15.1f}  "
                  f"{np.median(b) / np.median(q):7.1f}x")  # fmt: skip


if __name__ == "__main__":
    main()
