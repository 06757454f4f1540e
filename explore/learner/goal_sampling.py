"""Coverage-seeking goal selection: goals where the reached outcomes are sparse.

Option ``goal_sampling`` of every goal-exploration strategy, per module of its goal space:

- ``"uniform"`` (the default, the paper's): one draw of the strategy's goal distribution
  (option ``goals``: uniform in the bounds reached so far, the box, or N(0, 1)). No state is
  kept here and the generator is used exactly as before this option existed.
- ``"density"`` (after MEGA, Pitis et al., ICML 2020): ``N_CANDIDATES`` candidates among the
  module's reached outcomes (the reachability guard below says which), each scored by a
  Gaussian kernel density over ``N_REFERENCE`` reached outcomes (a fresh random subsample each
  time: the cost does not grow with the history), and the least dense candidate is the goal.
  The goal is an outcome the module reached, where few others lie.
- ``"frontier"``: the least dense candidate as above, then one bandwidth further, away from
  the reached outcomes around it (along its distance to the kernel-weighted mean of the
  reference outcomes, the mean-shift direction reversed): a goal just beyond the edge of the
  reached set.

- ``"sparse"``: ``N_DRAWS`` draws of the strategy's goal distribution (as "uniform"), the
  least dense under the same kernel density the goal, among those within
  ``GUARD_BANDWIDTHS`` bandwidths of a reference outcome (its guard: a radius); uniform goals
  with a push towards the holes of the reached set.

Coordinates: every outcome is scaled by the module's bounds so far, (o - low) / (high - low),
so one bandwidth rule serves engineered features, latent codes and image positions alike.

Bandwidth: Scott's rule on the scaled reference outcomes, per coordinate
h_i = M^(-1/(d+4)) * sd_i (Scott, Multivariate Density Estimation, 1992; M outcomes in d
dimensions), at least ``MIN_BANDWIDTH``. For M = 500 outcomes spread uniformly in 3-D it gives
0.12, near MEGA's fixed 0.1 on normalised goals.

Reachability guard, three parts.
- Context: where the scene is not reset between episodes (the twin: the ball stays where it
  lies), the candidates are the ``N_CANDIDATES`` reached outcomes, among ``N_POOL`` drawn,
  whose episodes started from the context nearest the current one (the inverse model's
  context: the ball's features, or the previous outcome's code): outcomes reached from here.
  Without it, on the twin, density chose goals reached once from elsewhere and moved the ball
  in fewer episodes than uniform goals (docs/goal_exploration.md, "Choosing goals"). Where the
  scene resets (Arm-2-Balls: no context) candidates are drawn among all reached outcomes, as
  MEGA's.
- Misses (option ``goal_misses``, default ``GOAL_MISSES``): a reached outcome stops being a
  candidate once ``goal_misses`` goal episodes that aimed at it exactly (``density``'s goals
  are reached outcomes) ended farther than ``MISS_RADIUS`` from it (scaled coordinates,
  Euclidean): an outcome reached once may not be reached again (a bump against the wall).
- Radius: ``frontier``'s goals are not reached outcomes, so no miss is counted for them; a
  goal lies one bandwidth beyond a reached outcome, never farther.

Arithmetic: distances summed over the coordinates in a fixed order, and ``plumbing.fixed_order``'s
exp and log (numpy's run SIMD versions chosen by CPU), so that a goal is the same bits on every
machine (docs/determinism.md).

State is a deterministic function of the records learnt (outcomes and miss counts); all
randomness comes from the generator passed to ``goal`` (the episode's), so a resumed run
that replays its history proposes the same goals.
"""

from __future__ import annotations

from typing import Literal

import numpy as np

from plumbing import fixed_order

GoalSampling = Literal["uniform", "density", "frontier", "sparse"]
GOAL_SAMPLINGS: tuple[str, ...] = ("uniform", "density", "frontier", "sparse")
# MEGA (spitis/mrl, ``DensityAchievedGoalCuriosity``) scores a few hundred sampled achieved
# goals under a kernel density of the buffer; here 100 candidates and 500 reference outcomes,
# a guess sized by bench/bench_goal_sampling.py to keep a choice well under 1 ms.
N_CANDIDATES = 100
N_REFERENCE = 500
N_POOL = 1000  # outcomes drawn, of which the N_CANDIDATES started nearest the context (a guess)
N_DRAWS = 10  # "sparse": draws of the goal distribution scored (a guess)
GUARD_BANDWIDTHS = 3.0  # "sparse": a draw farther than this from every reference is dropped
MIN_BANDWIDTH = 1e-3  # scaled units: a coordinate that never varied gets this (a guess)
MISS_RADIUS = 0.1  # scaled units: MEGA's bandwidth on normalised goals, used as a radius
GOAL_MISSES = 3  # misses before an outcome stops being a candidate (a guess; 0: no guard)
_GROW = 1024  # initial rows of a module's outcome store (doubled when full)


def scott_bandwidth(points: np.ndarray) -> np.ndarray:
    """Scott's rule per coordinate, h_i = n^(-1/(d+4)) * sd_i, at least ``MIN_BANDWIDTH``.

    Args:
        points: (n, d) outcomes in scaled coordinates.
    Returns:
        (d,) bandwidths in the same units.
    """
    n, d = points.shape
    sd = points.std(axis=0) if n > 1 else np.zeros(d)
    factor = float(fixed_order.exp(fixed_order.log(float(n)) * (-1.0 / (d + 4))))  # n^(-1/(d+4))
    return np.maximum(factor * sd, MIN_BANDWIDTH)


def scaled_sq_distances(
    queries: np.ndarray, reference: np.ndarray, bandwidth: np.ndarray
) -> np.ndarray:
    """(c, m) squared distances of queries (c, d) to references (m, d), in bandwidth (d,)
    units, summed over the coordinates in order."""
    q, r = queries / bandwidth, reference / bandwidth
    sq = np.zeros((len(q), len(r)))
    diff = np.empty_like(sq)  # one buffer for every coordinate: no large temporaries
    for j in range(q.shape[1]):
        np.subtract(q[:, j, None], r[None, :, j], out=diff)
        diff *= diff
        sq += diff
    return sq


def kernel_log_density(
    queries: np.ndarray,
    reference: np.ndarray,
    bandwidth: np.ndarray,
    sq: np.ndarray | None = None,
) -> np.ndarray:
    """Log of a Gaussian kernel density (up to a constant) at each query.

    Args:
        queries: (c, d); reference: (m, d); bandwidth: (d,), all in the same units.
        sq: their ``scaled_sq_distances`` when already computed.
    Returns:
        (c,) log sum_j exp(-|q - r_j|^2 / 2) over the reference, in bandwidth units.
    """
    if sq is None:
        sq = scaled_sq_distances(queries, reference, bandwidth)
    e = -0.5 * sq
    top = e.max(axis=1)  # our own log-sum-exp: scipy's costs 1.2 ms at (100, 500)
    # numpy's pairwise sum along a row: an order fixed by its source, not by the CPU
    total = np.add.reduce(fixed_order.exp(e - top[:, None]), axis=1)
    return top + fixed_order.log(total)


class OutcomeStore:
    """One module's reached outcomes (raw coordinates) and, per outcome, the goal episodes
    that aimed at it and missed (the guard)."""

    def __init__(self, dim: int, context_dim: int = 0) -> None:
        self.points = np.empty((_GROW, dim))
        self.contexts = np.empty((_GROW, context_dim))
        self.misses = np.zeros(_GROW, dtype=np.int32)
        self.n = 0
        self._index: dict[bytes, int] = {}  # an outcome's bytes -> its first row

    def add(self, outcome: np.ndarray, context: np.ndarray) -> None:
        """Store one finite outcome, shape (dim,), and its episode's context, shape
        (context_dim,)."""
        if self.n == len(self.points):
            self.points = np.vstack([self.points, np.empty_like(self.points)])
            self.contexts = np.vstack([self.contexts, np.empty_like(self.contexts)])
            self.misses = np.concatenate([self.misses, np.zeros_like(self.misses)])
        self.points[self.n] = outcome
        self.contexts[self.n] = context
        self._index.setdefault(outcome.tobytes(), self.n)
        self.n += 1

    def aimed_at(self, goal: np.ndarray) -> int | None:
        """The row of the stored outcome equal to ``goal``, or None."""
        return self._index.get(goal.tobytes())


class GoalSampler:
    """Density-based goal choice over each module's reached outcomes (module doc).

    Args:
        mode: "density" or "frontier".
        dims: each module's dimension.
        goal_misses: the guard's count (0: no guard).
        context_dim: the inverse model's context size (0: a scene reset between episodes).
    """

    def __init__(
        self, mode: str, dims: list[int], goal_misses: int = GOAL_MISSES, context_dim: int = 0
    ) -> None:
        if mode not in ("density", "frontier", "sparse"):
            raise ValueError(f"goal sampling {mode!r} keeps no outcomes")
        self.mode = mode
        self.goal_misses = goal_misses
        self.context_dim = context_dim
        self.stores = [OutcomeStore(d, context_dim) for d in dims]

    def learn(
        self,
        parts: list[np.ndarray | None],
        module: int,
        goal: np.ndarray | None,
        low: np.ndarray,
        high: np.ndarray,
        context: np.ndarray | None = None,
    ) -> None:
        """One episode: its outcome per module (None: not seen), and, for a goal episode,
        its module and goal with the module's bounds (after this episode) to judge a miss;
        ``context``: the episode's context, shape (context_dim,) (None: zeros)."""
        if goal is not None and 0 <= module < len(parts) and parts[module] is not None:
            store = self.stores[module]
            g = np.asarray(goal, dtype=float)
            j = store.aimed_at(g)
            if j is not None:
                span = _span(low, high)
                miss = fixed_order.norm((np.asarray(parts[module], dtype=float) - g) / span)
                if miss > MISS_RADIUS:
                    store.misses[j] += 1
        c = np.zeros(self.context_dim) if context is None else np.asarray(context, dtype=float)
        for k, o in enumerate(parts):
            if o is None:
                continue
            o = np.asarray(o, dtype=float)
            if np.all(np.isfinite(o)):
                self.stores[k].add(o, c)

    def goal(
        self,
        module: int,
        rng: np.random.Generator,
        low: np.ndarray,
        high: np.ndarray,
        context: np.ndarray | None = None,
        drawn: np.ndarray | None = None,
    ) -> np.ndarray | None:
        """A goal in ``module`` (raw coordinates, shape (d,)), or None when no reached
        outcome is a candidate (the caller then draws a uniform goal); ``context``: the
        inverse model's context now, shape (context_dim,); ``drawn``: "sparse"'s candidates,
        (N_DRAWS, d) draws of the goal distribution."""
        store = self.stores[module]
        n = store.n
        if n == 0:
            return None
        if self.mode == "sparse":
            assert drawn is not None
            return self._sparse(store, rng, low, high, drawn)
        cand = self._candidates(store, rng, context)
        ref = np.arange(n) if n <= N_REFERENCE else rng.integers(0, n, N_REFERENCE)
        if self.goal_misses:
            cand = cand[store.misses[cand] < self.goal_misses]
            if len(cand) == 0:
                return None
        span = _span(low, high)
        lo = np.where(np.isfinite(low), low, 0.0)
        c = (store.points[cand] - lo) / span
        r = (store.points[ref] - lo) / span
        h = scott_bandwidth(r)
        i = int(np.argmin(kernel_log_density(c, r, h)))  # ties: the first candidate
        if self.mode == "density":
            return store.points[cand[i]].copy()
        return lo + span * frontier_step(c[i], r, h)

    def _sparse(
        self,
        store: OutcomeStore,
        rng: np.random.Generator,
        low: np.ndarray,
        high: np.ndarray,
        drawn: np.ndarray,
    ) -> np.ndarray:
        """The least dense of ``drawn`` within ``GUARD_BANDWIDTHS`` of a reference
        outcome (the first draw when none is)."""
        n = store.n
        ref = np.arange(n) if n <= N_REFERENCE else rng.integers(0, n, N_REFERENCE)
        span = _span(low, high)
        lo = np.where(np.isfinite(low), low, 0.0)
        r = (store.points[ref] - lo) / span
        h = scott_bandwidth(r)
        c = (np.asarray(drawn, dtype=float) - lo) / span
        sq = scaled_sq_distances(c, r, h)
        near = sq.min(axis=1) <= GUARD_BANDWIDTHS**2
        if not near.any():
            return np.asarray(drawn[0], dtype=float)
        logp = np.where(near, kernel_log_density(c, r, h, sq), np.inf)
        return np.asarray(drawn[int(np.argmin(logp))], dtype=float)

    def _candidates(
        self, store: OutcomeStore, rng: np.random.Generator, context: np.ndarray | None
    ) -> np.ndarray:
        """Rows of the candidate outcomes: all while there are few, else ``N_CANDIDATES``
        drawn, or with a context the ``N_CANDIDATES`` of ``N_POOL`` drawn that started
        nearest to it (module doc)."""
        n = store.n
        if self.context_dim == 0 or context is None:
            return np.arange(n) if n <= N_CANDIDATES else rng.integers(0, n, N_CANDIDATES)
        if n <= N_CANDIDATES:
            return np.arange(n)
        pool = rng.integers(0, n, N_POOL)  # drawn, not in order: ties go to chance
        gap = fixed_order.sq_distances(store.contexts[pool], context)
        order = np.argsort(gap, kind="stable")  # ties: the earlier draw
        return pool[order[:N_CANDIDATES]]


def frontier_step(x: np.ndarray, reference: np.ndarray, bandwidth: np.ndarray) -> np.ndarray:
    """``x`` moved one bandwidth away from the kernel-weighted mean of ``reference`` (the
    reference points equal to ``x`` left out; with none near, away from their plain mean).

    Args:
        x: (d,); reference: (m, d); bandwidth: (d,), all in scaled coordinates.
    Returns:
        (d,) the frontier goal, in scaled coordinates.
    """
    z = (reference - x) / bandwidth
    sq = fixed_order.sq_distances(z, np.zeros(z.shape[1]))
    others = sq > 0
    if not others.any():
        return x.copy()
    w = fixed_order.exp(-0.5 * (sq[others] - sq[others].min()))
    # sums over the reference down axis 0: row after row, an order fixed by numpy's source
    mean = np.add.reduce(w[:, None] * reference[others], axis=0) / np.add.reduce(w)
    v = (x - mean) / bandwidth
    norm = fixed_order.norm(v)
    if norm == 0.0:
        return x.copy()
    return x + bandwidth * v / norm


def _span(low: np.ndarray, high: np.ndarray) -> np.ndarray:
    """high - low per coordinate, 1 where not yet finite or zero."""
    span = np.asarray(high, dtype=float) - np.asarray(low, dtype=float)
    return np.where(np.isfinite(span) & (span > 0), span, 1.0)


def make_sampler(
    mode: str, dims: list[int], goal_misses: int = GOAL_MISSES, context_dim: int = 0
) -> GoalSampler | None:
    """The sampler of ``goal_sampling`` = ``mode``; None for "uniform" (nothing kept)."""
    if mode == "uniform":
        return None
    return GoalSampler(mode, dims, goal_misses, context_dim)
