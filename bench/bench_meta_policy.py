"""Meta-policy query time as the history grows: 1k, 10k and 100k stored episodes.

Issue 6's benchmark. For each size, a ``MetaPolicy`` with one module is filled with random
episodes (context and outcome uniform in [-1, 1], 48 parameters), then timed on random
queries (``infer``: nearest neighbour plus exploration noise, sigma 0.05). The peer, in the
same run on the same points, is a brute-force scan (numpy distance to every point, argmin),
which is what a query costs without the tree. Three shapes:

- the engineered goal space (context 3 + outcome 3), uniform in [-1, 1];
- a VAE's (context 10 + outcome 10), uniform in [-1, 1]^20: the worst case, where no k-d tree
  helps (every cell of a 20-D tree borders the query's);
- a VAE's (context 10 + outcome 10) as the twin gives it: both halves are a smooth function of
  a 2-D ball position (a fixed random map, tanh(u A + b), plus 0.01 noise), and the goals
  are uniform in the bounding box of the outcomes, as RGE samples them. Real latents are far
  from uniform: those of a 5000-episode rge-vae run on the twin put 98% of their variance in
  one principal component (measured on seed 0 of the earlier twin campaign, with its VAE).

Prints per size: the insertion cost per episode (amortised over the tree rebuilds), the
points a query scans (those left outside the tree until its next rebuild; all of them where
there is no tree, above 8 dimensions), the median and 99th percentile of a query, the
brute-force median and the speed-up over it.

    .venv/bin/python bench/bench_meta_policy.py [--sizes 1000 10000 100000] [--queries 2000]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from explore.learner.dmp import N_PARAMS
from explore.learner.meta_policy import MetaPolicy


class Uniform:
    """Contexts, outcomes and goals uniform in [-1, 1]."""

    def __init__(self, c_dim: int, o_dim: int) -> None:
        self.c_dim, self.o_dim = c_dim, o_dim

    def episodes(self, n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """Contexts (n, c_dim) and outcomes (n, o_dim)."""
        return rng.uniform(-1, 1, (n, self.c_dim)), rng.uniform(-1, 1, (n, self.o_dim))

    def query(self, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """One (context (c_dim,), goal (o_dim,))."""
        return rng.uniform(-1, 1, self.c_dim), rng.uniform(-1, 1, self.o_dim)


class BallLatents(Uniform):
    """Context and outcome latents (dim each) that are a smooth map of a 2-D ball position."""

    def __init__(self, dim: int, rng: np.random.Generator) -> None:
        super().__init__(dim, dim)
        self.a, self.b = rng.normal(size=(2, dim)), rng.normal(0, 0.5, dim)
        self.lo, self.hi = -np.ones(dim), np.ones(dim)

    def _latent(self, u: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        return np.tanh(u @ self.a + self.b) + rng.normal(0, 0.01, (*u.shape[:-1], self.o_dim))

    def episodes(self, n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        c = self._latent(rng.uniform(-1, 1, (n, 2)), rng)
        o = self._latent(rng.uniform(-1, 1, (n, 2)), rng)
        self.lo, self.hi = o.min(axis=0), o.max(axis=0)
        return c, o

    def query(self, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        return self._latent(rng.uniform(-1, 1, 2), rng), rng.uniform(self.lo, self.hi)


def shapes(rng: np.random.Generator) -> dict[str, Uniform]:
    return {
        "engineered (3 + 3), uniform": Uniform(3, 3),
        "VAE latents (10 + 10), uniform: the worst case": Uniform(10, 10),
        "VAE latents (10 + 10) of a 2-D ball position": BallLatents(10, rng),
    }


def fill(policy: MetaPolicy, shape: Uniform, n: int, rng: np.random.Generator) -> float:
    """Add ``n`` episodes of ``shape``; returns the mean seconds per ``add``."""
    contexts, outcomes = shape.episodes(n, rng)
    thetas = rng.uniform(-1, 1, (n, N_PARAMS))
    t0 = time.perf_counter()
    for i in range(n):
        policy.add(contexts[i], [outcomes[i]], thetas[i])
    return (time.perf_counter() - t0) / n


def time_queries(
    policy: MetaPolicy, shape: Uniform, queries: int, rng: np.random.Generator
) -> np.ndarray:
    """Seconds of each of ``queries`` ``infer`` calls on queries of ``shape``."""
    out = np.empty(queries)
    for k in range(queries):
        c, g = shape.query(rng)
        t0 = time.perf_counter()
        policy.infer(0, c, g, rng, 0.05)
        out[k] = time.perf_counter() - t0
    return out


def time_brute(
    points: np.ndarray, shape: Uniform, queries: int, rng: np.random.Generator
) -> np.ndarray:
    """Seconds of each of ``queries`` brute-force nearest-neighbour scans over ``points``."""
    out = np.empty(queries)
    for k in range(queries):
        q = np.concatenate(shape.query(rng))
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
    for label, shape in shapes(rng).items():
        print(f"\n{label}")
        print("  episodes  add_us  scanned  query_us_median  query_us_p99  "
              "brute_us_median  speed-up")  # fmt: skip
        for n in args.sizes:
            policy = MetaPolicy(shape.c_dim, [shape.o_dim], N_PARAMS)
            add_s = fill(policy, shape, n, rng)
            index = policy.indexes[0]
            q = time_queries(policy, shape, args.queries, rng) * 1e6
            b = time_brute(index.points, shape, args.queries, rng) * 1e6
            outside = index.outside_tree
            print(f"  {n:8d}  {add_s * 1e6:6.1f}  {outside:7d}  {np.median(q):15.1f}  "
                  f"{np.percentile(q, 99):12.1f}  {np.median(b):15.1f}  "
                  f"{np.median(b) / np.median(q):7.1f}x")  # fmt: skip


if __name__ == "__main__":
    main()
