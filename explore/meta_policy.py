"""The meta-policy: (context, goal) -> motor parameters, by nearest neighbour.

The paper's inverse model (shared/REFERENCE.md): for a goal in a module's goal space, play the
parameters of the past episode whose (context, outcome) is nearest to (context, goal), plus
Gaussian exploration noise (sigma 0.05 in the [-1, 1] parameter space in simulation), clipped
to [-1, 1].

Queries stay fast as the history grows: a ``scipy.spatial.cKDTree`` holds the points up to the
last rebuild, a brute-force scan covers the points added since, and the tree is rebuilt when
the history has doubled (amortised O(log n) per insertion, O(log n + tail) per query).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy.spatial import cKDTree

DEFAULT_SIGMA = 0.05  # paper, simulation experiments ([-1, 1] parameter space)
MIN_TREE = 64  # below this many points a brute-force scan is as fast as a tree (guess)


class NearestNeighbourIndex:
    """Growing set of points of dimension ``dim`` with exact 1-NN queries (Euclidean).

    Ties between equally distant points go to the lowest index.
    """

    def __init__(self, dim: int) -> None:
        if dim < 1:
            raise ValueError(f"index dimension must be at least 1, got {dim}")
        self.dim = dim
        self._points = np.empty((MIN_TREE, dim))
        self._n = 0
        self._tree: cKDTree | None = None
        self._n_tree = 0  # points covered by the tree: [0, n_tree)

    def __len__(self) -> int:
        return self._n

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
        self._points[self._n] = p
        self._n += 1
        if self._n >= MIN_TREE and self._n >= 2 * max(self._n_tree, MIN_TREE // 2):
            self._tree = cKDTree(self._points[: self._n].copy())
            self._n_tree = self._n
        return self._n - 1

    def nearest(self, query: np.ndarray) -> tuple[int, float]:
        """Index and distance of the point nearest to ``query`` (dim,). Raises if empty."""
        if self._n == 0:
            raise ValueError("nearest neighbour of an empty index")
        q = np.asarray(query, dtype=float).reshape(-1)
        if q.shape != (self.dim,):
            raise ValueError(f"query has shape {q.shape}, expected ({self.dim},)")
        best_i, best_d = -1, np.inf
        if self._tree is not None:
            d, i = self._tree.query(q, k=1)
            best_i, best_d = int(i), float(d)
            # cKDTree breaks ties arbitrarily: look for an equally distant lower index
            ties = self._tree.query_ball_point(q, best_d * (1 + 1e-12) + 1e-300)
            if ties:
                tied = np.asarray(ties)
                dist = np.linalg.norm(self._points[tied] - q, axis=1)
                tied = tied[dist <= best_d]
                if len(tied):
                    best_i = int(tied.min())
        tail = self._points[self._n_tree : self._n]
        if len(tail):
            dist = np.linalg.norm(tail - q, axis=1)
            j = int(np.argmin(dist))
            if dist[j] < best_d:
                best_i, best_d = self._n_tree + j, float(dist[j])
        return best_i, best_d


class MetaPolicy:
    """One nearest-neighbour database per goal-space module, sharing the parameters.

    Args:
        context_dim: size of the context vector c (may be 0).
        module_dims: size of each module's goal/outcome vector.
        n_params: size of the parameter vector theta (48 for the DMPs).
    """

    def __init__(self, context_dim: int, module_dims: Sequence[int], n_params: int) -> None:
        self.context_dim = context_dim
        self.module_dims = tuple(int(d) for d in module_dims)
        self.n_params = n_params
        self.indexes = [NearestNeighbourIndex(context_dim + d) for d in self.module_dims]
        self.thetas: list[list[np.ndarray]] = [[] for _ in self.module_dims]

    def add(self, context: np.ndarray, outcomes: Sequence[np.ndarray | None], theta: np.ndarray):
        """Record an episode: ``context`` (context_dim,), ``outcomes[k]`` (module_dims[k],) or
        None where module k saw nothing, ``theta`` (n_params,)."""
        theta = np.asarray(theta, dtype=float).reshape(-1)
        if theta.shape != (self.n_params,):
            raise ValueError(f"theta has shape {theta.shape}, expected ({self.n_params},)")
        c = np.asarray(context, dtype=float).reshape(-1)
        for k, o in enumerate(outcomes):
            if o is None or not np.all(np.isfinite(o)):
                continue
            self.indexes[k].add(np.concatenate([c, np.asarray(o, dtype=float).reshape(-1)]))
            self.thetas[k].append(theta)

    def size(self, module: int) -> int:
        return len(self.indexes[module])

    def nearest_theta(self, module: int, context: np.ndarray, goal: np.ndarray) -> np.ndarray:
        """Parameters of the episode nearest to (context, goal) in ``module``, shape (n_params,)."""
        q = np.concatenate([np.asarray(context, float).reshape(-1), np.asarray(goal, float)])
        i, _ = self.indexes[module].nearest(q)
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
