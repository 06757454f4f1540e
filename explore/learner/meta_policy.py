"""The meta-policy: (context, goal) -> motor parameters, by nearest neighbour.

The paper's inverse model (docs/facts.md): for a goal in a module's goal space, play the
parameters of the past episode whose (context, outcome) is nearest to (context, goal), plus
Gaussian exploration noise (sigma 0.05 in the [-1, 1] parameter space in simulation), clipped
to [-1, 1].

Queries stay fast as the history grows: a ``scipy.spatial.cKDTree`` holds the points up to the
last rebuild and a vectorised scan covers the points added since (the tail). The tree is rebuilt
when the history has doubled while it is small, then every ``rebuild_tail`` insertions (1024),
then every n/32 once that is larger. So the tail never holds more than max(1024, n/32) points,
and a rebuild (O(n log n)) costs O(log n) per insertion up to 32k points and O(32 log n) after.
A query costs a tree search plus a scan of at most that tail (``bench/bench_meta_policy.py``).
Above 8 dimensions (a VAE's 10 latents + 10 of context) a k-d tree prunes almost nothing, so
there is no tree: each query scans all points with one matrix-vector product.

One distance decides, the same bits on every machine: the squared distance summed over the
coordinates in order (``plumbing.fixed_order.sq_distances``), compared as it is (ties: the
lowest index). The tree and the matrix-vector product only propose candidates; they round
differently (cKDTree sums in its own order, the product is OpenBLAS's, whose kernel depends on
the CPU), so each proposes every point within a margin far above its rounding (relative 1e-9)
of the best it found, and the fixed-order distance chooses among them. The answer is then the
fixed-order nearest whatever the kernel: a kernel's error on a squared distance is below
d x 2^-53 of the squared norms involved, some 10^6 times smaller than the margin (the squared
norms and the margin are BLAS's too: they move the margin by an ulp, never the answer).

The first version rebuilt only when the history doubled: up to half of the points sat in the
tail, and at 100k stored episodes a query was no faster than a brute-force scan (1.7 ms in
6-D, 17 ms in 20-D).
"""

from __future__ import annotations

import hashlib
from collections.abc import Sequence

import numpy as np
from scipy.spatial import cKDTree

from plumbing.fixed_order import sq_distances

DEFAULT_SIGMA = 0.05  # paper, simulation experiments ([-1, 1] parameter space)
MIN_TREE = 64  # below this many points a brute-force scan is as fast as a tree (guess)
REBUILD_TAIL = 1024  # most points left outside the tree below 32k points (bench_meta_policy)
TAIL_FRACTION = 32  # beyond, at most n / 32 outside the tree (rebuild cost amortised, guess)
TREE_MAX_DIM = 8  # above, a k-d tree query costs about a full scan (bench_meta_policy: 6-D vs 20-D)
SMALL_SCAN = 256  # below, a plain distance scan beats the matrix-vector one (guess)
# relative margin around a candidate proposer's best (the tree's distance, the matrix-vector
# product's squared one): far above their rounding (module doc)
MARGIN = 1e-9
TIES = ("first", "spread")


class NearestNeighbourIndex:
    """Growing set of points of dimension ``dim`` with exact 1-NN queries (Euclidean).

    Up to ``tree_max_dim`` dimensions, a k-d tree plus a scan of the points added since its
    last rebuild. Above, a k-d tree prunes almost nothing (a query costs about a full scan:
    bench_meta_policy, VAE rows), so every query is a scan, done as one matrix-vector
    product on the stored squared norms, then exact distances for the few candidates it leaves.

    Distances are the fixed-order ones (module doc); ties between equally distant points go
    to the lowest index, so runs stay deterministic whatever the rebuild schedule and the
    machine. ``rebuild_tail``: the most points left outside the tree
    (before n / ``TAIL_FRACTION`` takes over); tests make it and ``tree_max_dim`` small.
    """

    def __init__(
        self, dim: int, rebuild_tail: int = REBUILD_TAIL, tree_max_dim: int = TREE_MAX_DIM
    ) -> None:
        if dim < 1:
            raise ValueError(f"index dimension must be at least 1, got {dim}")
        if rebuild_tail < 1:
            raise ValueError(f"rebuild_tail must be at least 1, got {rebuild_tail}")
        self.dim = dim
        self.rebuild_tail = rebuild_tail
        self.uses_tree = dim <= tree_max_dim
        self._points = np.empty((MIN_TREE, dim))
        self._sq = np.empty(MIN_TREE)  # squared norms of the points
        self._sq_max = 0.0
        self._n = 0
        self._tree: cKDTree | None = None
        self._n_tree = 0  # points covered by the tree: [0, n_tree)

    def __len__(self) -> int:
        return self._n

    @property
    def outside_tree(self) -> int:
        """Points added since the last rebuild, scanned at each query (all of them without
        a tree)."""
        return self._n - self._n_tree

    def _tail_limit(self) -> int:
        """How many points may sit outside the tree before it is rebuilt."""
        if self._n_tree == 0:
            return MIN_TREE
        bounded = min(self._n_tree, self.rebuild_tail)  # doubling while the tree is small
        return max(bounded, self._n_tree // TAIL_FRACTION)

    @property
    def points(self) -> np.ndarray:
        """All points so far, shape (n, dim) (a view: do not modify)."""
        return self._points[: self._n]

    def add(self, point: np.ndarray) -> int:
        """Append one point, shape (dim,); returns its index."""
        p = np.asarray(point, dtype=float).reshape(-1)
        if p.shape != (self.dim,):
            raise ValueError(f"point has shape {p.shape}, expected ({self.dim},)")
        if not np.all(np.isfinite(p)):
            raise ValueError("point has NaN or infinite coordinates")
        if self._n == len(self._points):
            grown = np.empty((2 * len(self._points), self.dim))
            grown[: self._n] = self._points[: self._n]
            self._points = grown
            self._sq = np.concatenate([self._sq[: self._n], np.empty(self._n)])
        self._points[self._n] = p
        # the scan's filter only: BLAS's rounding here changes no answer (module doc)
        self._sq[self._n] = sq = float(p @ p)
        self._sq_max = max(self._sq_max, sq)
        self._n += 1
        if self.uses_tree and self._n - self._n_tree >= self._tail_limit():
            self._tree = cKDTree(self._points[: self._n].copy())
            self._n_tree = self._n
        return self._n - 1

    def _scan(self, q: np.ndarray, start: int) -> tuple[int, float]:
        """Nearest of the points [start, n) to ``q``: index (lowest of ties), squared
        distance (fixed order)."""
        pts = self._points[start : self._n]
        if len(pts) <= SMALL_SCAN:
            sq = sq_distances(pts, q)
            j = int(np.argmin(sq))  # the first of equal minima
            return start + j, float(sq[j])
        # |p - q|^2 - |q|^2 = |p|^2 - 2 p.q, as BLAS rounds it: candidates within the margin
        approx = self._sq[start : self._n] - 2.0 * (pts @ q)
        tol = MARGIN * (self._sq_max + float(q @ q)) + 1e-300
        cand = np.flatnonzero(approx <= approx.min() + tol)
        sq = sq_distances(pts[cand], q)
        j = int(np.argmin(sq))
        return start + int(cand[j]), float(sq[j])

    def nearest_sq(self, query: np.ndarray) -> tuple[int, float]:
        """Index of the point nearest to ``query`` (dim,) (the lowest of ties) and its squared
        distance, both by the fixed-order distance. Raises if empty."""
        if self._n == 0:
            raise ValueError("nearest neighbour of an empty index")
        q = np.asarray(query, dtype=float).reshape(-1)
        if q.shape != (self.dim,):
            raise ValueError(f"query has shape {q.shape}, expected ({self.dim},)")
        if self._tree is None:
            return self._scan(q, 0)
        d, _ = self._tree.query(q, k=1)
        # the tree's own distance rounds in its own order: every point it places within the
        # margin of its best is a candidate, the fixed-order distance chooses
        near = self._tree.query_ball_point(q, d * (1 + MARGIN) + 1e-300)
        if len(near) > 1:
            near.sort()
        sq = sq_distances(self._points[near], q)
        j = int(np.argmin(sq))
        best_i, best_sq = int(near[j]), float(sq[j])
        if self._n_tree < self._n:
            i, s = self._scan(q, self._n_tree)
            if s < best_sq:  # the tail's indices are above the tree's: ties stay with it
                best_i, best_sq = i, s
        return best_i, best_sq

    def nearest(self, query: np.ndarray) -> tuple[int, float]:
        """Index and distance of the point nearest to ``query`` (dim,) (``nearest_sq``, the
        square root taken). Raises if empty."""
        i, sq = self.nearest_sq(query)
        return i, float(np.sqrt(sq))

    def nearest_spread(self, query: np.ndarray) -> tuple[int, float]:
        """Like ``nearest``, but among the points at exactly the smallest distance the one
        picked by a hash of ``query`` (uniform over them as queries vary, the same for the same
        query and points: a run stays a function of its seed). Scans every point."""
        if self._n == 0:
            raise ValueError("nearest neighbour of an empty index")
        q = np.asarray(query, dtype=float).reshape(-1)
        if q.shape != (self.dim,):
            raise ValueError(f"query has shape {q.shape}, expected ({self.dim},)")
        sq = sq_distances(self._points[: self._n], q)
        best = float(sq.min())
        return spread_pick(q, np.flatnonzero(sq == best)), float(np.sqrt(best))


def spread_pick(query: np.ndarray, tied: np.ndarray) -> int:
    """The one of the equally near point indices ``tied`` (k,) that ties "spread" answers
    ``query`` (float64, (dim,)) with: picked by a hash of the query's bytes."""
    if len(tied) == 1:
        return int(tied[0])
    key = int.from_bytes(hashlib.blake2b(query.tobytes(), digest_size=8).digest(), "little")
    return int(tied[key % len(tied)])


class MetaPolicy:
    """One nearest-neighbour database per goal-space module, sharing the parameters.

    Args:
        context_dim: size of the context vector c (may be 0).
        module_dims: size of each module's goal/outcome vector.
        n_params: size of the parameter vector theta (48 for the DMPs).
        ties: which of several equally near episodes answers a query: ``"first"`` (the
            default: the earliest, the same one for every query) or ``"spread"`` (one picked
            by a hash of the query, ``NearestNeighbourIndex.nearest_spread``).
        context_weight: factor w on the context's coordinates in the distance, so a query
            (c, g) is answered by the stored (c', o') nearest in w² |c - c'|² + |g - o'|²
            (1, the default: the joint (context, outcome) search of the paper and explauto;
            larger: the replayed episode started from a context nearer the current one, the
            inverse model conditioned on the context as w grows). Must be positive.

    ``varied(module)`` says whether a module has seen two different (context, outcome) points:
    explauto's ``NonParametric`` (the original ArmBalls campaign's inverse model,
    ``sensorimotor_model/non_parametric.py``, ``bootstrapped_s``) answers a module that has
    not with uniform random parameters instead of a neighbour (docs/results_armballs.md,
    "Stalls: cause and fix"); the strategy decides.
    """

    def __init__(
        self,
        context_dim: int,
        module_dims: Sequence[int],
        n_params: int,
        ties: str = "first",
        context_weight: float = 1.0,
    ) -> None:
        if ties not in TIES:
            raise ValueError(f"ties must be one of {', '.join(TIES)}, got {ties!r}")
        if not context_weight > 0:
            raise ValueError(f"context_weight must be positive, got {context_weight}")
        self.context_weight = float(context_weight)
        self.context_dim = context_dim
        self.module_dims = tuple(int(d) for d in module_dims)
        self.n_params = n_params
        self.ties = ties
        self.indexes = [NearestNeighbourIndex(context_dim + d) for d in self.module_dims]
        self.thetas: list[list[np.ndarray]] = [[] for _ in self.module_dims]
        self._varied = [False] * len(self.module_dims)

    def add(self, context: np.ndarray, outcomes: Sequence[np.ndarray | None], theta: np.ndarray):
        """Record an episode: ``context`` (context_dim,), ``outcomes[k]`` (module_dims[k],) or
        None where module k saw nothing, ``theta`` (n_params,)."""
        theta = np.asarray(theta, dtype=float).reshape(-1)
        if theta.shape != (self.n_params,):
            raise ValueError(f"theta has shape {theta.shape}, expected ({self.n_params},)")
        c = self.context_weight * np.asarray(context, dtype=float).reshape(-1)
        for k, o in enumerate(outcomes):
            if o is None or not np.all(np.isfinite(o)):
                continue
            point = np.concatenate([c, np.asarray(o, dtype=float).reshape(-1)])
            index = self.indexes[k]
            if not self._varied[k] and len(index) and not np.array_equal(point, index.points[0]):
                self._varied[k] = True
            index.add(point)
            self.thetas[k].append(theta)

    def size(self, module: int) -> int:
        return len(self.indexes[module])

    def varied(self, module: int) -> bool:
        """Whether ``module`` has recorded two different (context, outcome) points."""
        return self._varied[module]

    def nearest_theta(self, module: int, context: np.ndarray, goal: np.ndarray) -> np.ndarray:
        """Parameters of the episode nearest to (context, goal) in ``module``, shape (n_params,)."""
        c = self.context_weight * np.asarray(context, float).reshape(-1)
        q = np.concatenate([c, np.asarray(goal, float)])
        index = self.indexes[module]
        i, _ = index.nearest_spread(q) if self.ties == "spread" else index.nearest(q)
        return self.thetas[module][i]

    def infer(
        self,
        module: int,
        context: np.ndarray,
        goal: np.ndarray,
        rng: np.random.Generator,
        sigma: float = DEFAULT_SIGMA,
    ) -> np.ndarray:
        """Nearest parameters plus N(0, sigma^2) noise (none when sigma is 0), clipped to
        [-1, 1]; shape (n_params,)."""
        theta = self.nearest_theta(module, context, goal)
        if sigma > 0:
            theta = theta + rng.normal(0.0, sigma, self.n_params)
        return np.clip(theta, -1.0, 1.0)
