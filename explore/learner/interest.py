"""Learning-progress interest of goal-space modules (the paper's MGE module selection).

Per module k (the paper's modular goal exploration, docs/facts.md):
- competence of reaching o for goal g: ``"scaled"`` (the default) c(g, o) = -min(||g - o|| /
  scale, 1), in [-1, 0], scale the diagonal of the module's outcome bounds; or ``"distance"``
  c(g, o) = -min(||g - o||, 2), the original ArmBalls campaign's (explauto's
  ``competence_dist`` with ``dist_max`` = 2, set by its interest models,
  ``ExplorationAlgorithms/interest_model.py``; docs/armballs.md);
- progress of an exploit episode: c(g, o) - c(g, o_old), where o_old is the outcome reached for
  the previous goal of module k nearest to g (0 for the first goal);
- interest: ``"window"`` (the default) |mean of the last ``window`` progresses|; or
  ``"exponential"`` |p| with p += (progress - p) / window after each exploit episode, p starting
  at ``start`` (default 1e-5, the original's ``update_interest``; its ``win_size`` is this
  window);
- module choice: with probability ``random_choice`` uniformly, else in proportion to interest
  (uniformly while every interest is 0): the distribution of explauto's ``prop_choice``.
Only noise-free "exploit" episodes update interests; which goal-directed episodes enter the
goal history is the caller's choice (``remember``): every one in our schedule, one per goal
(its exploit) in the original's.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Sequence

import numpy as np

from plumbing.fixed_order import distance, sq_distances

RANDOM_CHOICE = 0.1  # paper: 10% of module choices at random
# Paper: 1000 episodes in simulation, 200 on the rig, for runs of ~10k episodes. Our CPU runs are
# a few thousand episodes with ~1 exploit episode in 5 spread over the modules: a guess, scaled.
WINDOW = 50
AVERAGES = ("window", "exponential")
COMPETENCES = ("scaled", "distance")
# The original's competence cap (interest_model.py: ``self.dist_max = 2``, the diagonal it
# computed and commented out would have been 2 sqrt(d) for its [-1, 1]^d goal boxes).
COMPETENCE_DIST_MAX = 2.0
# The original's starting progress and interest (interest_model.py: ``current_progress = 1e-5``)
START_PROGRESS = 1e-5


class ModuleInterest:
    """Interests of ``n_modules`` modules with goal dimensions ``dims``.

    Args:
        dims: goal dimension of each module.
        window: the window (``average="window"``) or the exponential average's time constant
            (``"exponential"``), in exploit episodes of the module.
        random_choice: share of module choices made uniformly.
        average: ``"window"`` or ``"exponential"`` (module doc).
        competence: ``"scaled"`` or ``"distance"`` (module doc).
        start: the exponential average's starting value, every module's (default
            ``START_PROGRESS``, the original's).
    """

    def __init__(
        self,
        dims: Sequence[int],
        window: int = WINDOW,
        random_choice: float = RANDOM_CHOICE,
        average: str = "window",
        competence: str = "scaled",
        start: float = START_PROGRESS,
    ) -> None:
        if not 0.0 <= random_choice <= 1.0:
            raise ValueError(f"random_choice must be in [0, 1], got {random_choice}")
        if window < 1:
            raise ValueError(f"interest window must be at least 1, got {window}")
        if average not in AVERAGES:
            raise ValueError(f"interest average must be one of {', '.join(AVERAGES)}")
        if competence not in COMPETENCES:
            raise ValueError(f"competence must be one of {', '.join(COMPETENCES)}")
        if not start >= 0.0:
            raise ValueError(f"interest start must be >= 0, got {start}")
        self.dims = tuple(dims)
        self.window = window
        self.random_choice = random_choice
        self.average = average
        self.competence_kind = competence
        self.progress = [deque(maxlen=window) for _ in self.dims]
        self.smoothed = [float(start)] * len(self.dims)  # the exponential average
        self.goals: list[list[np.ndarray]] = [[] for _ in self.dims]
        self.reached: list[list[np.ndarray | None]] = [[] for _ in self.dims]

    @property
    def n_modules(self) -> int:
        return len(self.dims)

    def interests(self) -> np.ndarray:
        """Current interest of each module, shape (n_modules,), >= 0."""
        if self.average == "exponential":
            return np.abs(np.array(self.smoothed, dtype=float))
        # math.fsum: the correctly rounded sum, the same on every machine
        return np.array([abs(math.fsum(p) / len(p)) if p else 0.0 for p in self.progress])

    def probabilities(self) -> np.ndarray:
        """Module choice probabilities, shape (n_modules,), summing to 1."""
        n = self.n_modules
        interest = self.interests()
        total = math.fsum(interest)
        greedy = interest / total if total > 0 else np.full(n, 1.0 / n)
        return self.random_choice / n + (1.0 - self.random_choice) * greedy

    def choose(self, rng: np.random.Generator) -> int:
        return int(rng.choice(self.n_modules, p=self.probabilities()))

    def competence(self, goal: np.ndarray, reached: np.ndarray | None, scale: float) -> float:
        """The competence of reaching ``reached`` for ``goal`` (module doc); the worst one
        (-1 scaled, -2 distance) when nothing was reached. ``scale`` serves ``"scaled"``."""
        worst = -COMPETENCE_DIST_MAX if self.competence_kind == "distance" else -1.0
        if reached is None or not np.all(np.isfinite(reached)):
            return worst
        d = distance(goal, reached)
        if self.competence_kind == "distance":
            return -min(d, COMPETENCE_DIST_MAX)
        return -min(d / max(scale, 1e-9), 1.0)

    def update(
        self,
        module: int,
        goal: np.ndarray,
        reached: np.ndarray | None,
        exploit: bool,
        scale: float,
        remember: bool = True,
    ) -> float | None:
        """Account one goal-directed episode of ``module``; returns its progress if it was an
        exploit episode (which updates the interest), else None. ``remember``: add its (goal,
        outcome) to the module's goal history (the goals later progresses compare with)."""
        goal = np.asarray(goal, dtype=float)
        progress = None
        if exploit:
            c = self.competence(goal, reached, scale)
            past = self.goals[module]
            if past:
                d = sq_distances(np.asarray(past), goal)
                old = self.reached[module][int(np.argmin(d))]
                progress = c - self.competence(goal, old, scale)
            else:
                progress = 0.0
            self.progress[module].append(progress)
            self.smoothed[module] += (progress - self.smoothed[module]) / self.window
        if remember:
            self.goals[module].append(goal)
            self.reached[module].append(None if reached is None else np.asarray(reached, float))
        return progress
