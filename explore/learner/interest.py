"""Learning-progress interest of goal-space modules (the paper's MGE module selection).

Per module k (the paper's modular goal exploration, docs/facts.md):
- competence of reaching o for goal g: c(g, o) = -min(||g - o|| / scale, 1), in [-1, 0];
- progress of an exploit episode: c(g, o) - c(g, o_old), where o_old is the outcome reached for
  the previous goal of module k nearest to g (0 for the first goal);
- interest = |mean of the last ``window`` progresses|;
- module choice: with probability ``random_choice`` uniformly, else in proportion to interest
  (uniformly while every interest is 0).
Only noise-free "exploit" episodes update interests; every goal-directed episode of a module
adds its (goal, outcome) to that module's goal history.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence

import numpy as np

RANDOM_CHOICE = 0.1  # paper: 10% of module choices at random
# Paper: 1000 episodes in simulation, 200 on the rig, for runs of ~10k episodes. Our CPU runs are
# a few thousand episodes with ~1 exploit episode in 5 spread over the modules: a guess, scaled.
WINDOW = 50


class ModuleInterest:
    """Interests of ``n_modules`` modules with goal dimensions ``dims``."""

    def __init__(
        self, dims: Sequence[int], window: int = WINDOW, random_choice: float = RANDOM_CHOICE
    ) -> None:
        if not 0.0 <= random_choice <= 1.0:
            raise ValueError(f"random_choice must be in [0, 1], got {random_choice}")
        if window < 1:
            raise ValueError(f"interest window must be at least 1, got {window}")
        self.dims = tuple(dims)
        self.random_choice = random_choice
        self.progress = [deque(maxlen=window) for _ in self.dims]
        self.goals: list[list[np.ndarray]] = [[] for _ in self.dims]
        self.reached: list[list[np.ndarray | None]] = [[] for _ in self.dims]

    @property
    def n_modules(self) -> int:
        return len(self.dims)

    def interests(self) -> np.ndarray:
        """Current interest of each module, shape (n_modules,), >= 0."""
        return np.array([abs(float(np.mean(p))) if p else 0.0 for p in self.progress])

    def probabilities(self) -> np.ndarray:
        """Module choice probabilities, shape (n_modules,), summing to 1."""
        n = self.n_modules
        interest = self.interests()
        total = interest.sum()
        greedy = interest / total if total > 0 else np.full(n, 1.0 / n)
        return self.random_choice / n + (1.0 - self.random_choice) * greedy

    def choose(self, rng: np.random.Generator) -> int:
        return int(rng.choice(self.n_modules, p=self.probabilities()))

    @staticmethod
    def competence(goal: np.ndarray, reached: np.ndarray | None, scale: float) -> float:
        """-min(||goal - reached|| / scale, 1); -1 when nothing was reached."""
        if reached is None or not np.all(np.isfinite(reached)):
            return -1.0
        return -min(float(np.linalg.norm(goal - reached)) / max(scale, 1e-9), 1.0)

    def update(
        self, module: int, goal: np.ndarray, reached: np.ndarray | None, exploit: bool, scale: float
    ) -> float | None:
        """Account one goal-directed episode of ``module``; returns its progress if it was an
        exploit episode (which updates the interest), else None."""
        goal = np.asarray(goal, dtype=float)
        progress = None
        if exploit:
            c = self.competence(goal, reached, scale)
            past = self.goals[module]
            if past:
                d = np.linalg.norm(np.asarray(past) - goal, axis=1)
                old = self.reached[module][int(np.argmin(d))]
                progress = c - self.competence(goal, old, scale)
            else:
                progress = 0.0
            self.progress[module].append(progress)
        self.goals[module].append(goal)
        self.reached[module].append(None if reached is None else np.asarray(reached, float))
        return progress
