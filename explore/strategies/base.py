"""The strategy interface: what goal exploration (and random exploration) implement.

A strategy proposes motor parameters for the next episode from the context observed at the
rest pose, then learns from the stored record of that episode. Its state must be a
deterministic function of the records it was updated with, so that a resumed run rebuilds it
by replaying the history.
"""

from __future__ import annotations

import importlib
from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from explore.episode import Observation
from explore.record import EpisodeRecord


@dataclass
class Proposal:
    """What to play next.

    Attributes:
        theta: motor parameters, shape (48,), in [-1, 1].
        goal: the goal aimed at in the strategy's goal space, shape (g,) (empty for RPE).
        module: goal-space module index (-1 when none).
        kind: "random" (motor babbling), "explore" (goal + noise) or "exploit" (goal, no noise).
    """

    theta: np.ndarray
    goal: np.ndarray = field(default_factory=lambda: np.zeros(0))
    module: int = -1
    kind: str = "random"


class Strategy(ABC):
    """Base class of exploration strategies."""

    name: str = "strategy"
    #: whether ``propose`` needs ``context.image`` (a render/frame at the rest pose)
    needs_context_image: bool = False

    def __init__(self, **options: Any) -> None:
        self.options = options

    @abstractmethod
    def propose(self, context: Observation, rng: np.random.Generator) -> Proposal:
        """Motor parameters for the next episode."""

    def update(self, record: EpisodeRecord) -> None:  # noqa: B027 - optional hook
        """Learn from a finished episode (default: nothing)."""

    def phase(self) -> str:
        """A short label of what the strategy is doing now (for progress displays)."""
        return self.name


# name -> "module:Class"
# How to make the model a latent strategy needs (option ``vae``; the campaign's ``--vae`` or
# ``--betavae``). "vae" is the recipe of docs/results.md: a plain VAE (beta 1) collapses at
# CPU-sized schedules.
MAKE_VAE = {
    "vae": "ergo dataset outcomes --n 3000 --out data/outcomes.npz && "
    "ergo vae train --data data/outcomes.npz --out models/vae --beta 10 --capacity 10 "
    "--capacity-iterations 500 --iterations 700",
    "betavae": "ergo dataset outcomes --n 10000 --out data/outcomes.npz && "
    "ergo vae train --data data/outcomes.npz --out models/betavae --beta 4 --capacity 10",
    "sae": "ergo dataset outcomes --n 3000 --out data/outcomes.npz && "
    "ergo sae train --data data/outcomes.npz --out models/sae",
}

STRATEGIES: dict[str, str] = {
    "rpe": "explore.strategies.rpe:RandomParameterExploration",
    "rge-efr": "explore.strategies.goal_exploration:EngineeredGoalExploration",
    "mge-efr": "explore.strategies.goal_exploration:ModularEngineeredGoalExploration",
    "rge-vae": "explore.strategies.goal_exploration:LatentGoalExploration",
    "rge-betavae": "explore.strategies.goal_exploration:BetaLatentGoalExploration",
    "mge-vae": "explore.strategies.goal_exploration:ModularLatentGoalExploration",
    "mge-betavae": "explore.strategies.goal_exploration:ModularBetaLatentGoalExploration",
    "rge-online": "explore.strategies.online:OnlineLatentGoalExploration",
    "rge-sae": "explore.strategies.goal_exploration:SpatialGoalExploration",
    "mge-sae": "explore.strategies.goal_exploration:ModularSpatialGoalExploration",
}


class StrategyError(ValueError):
    """Unknown strategy or bad strategy options."""


def make_strategy(name: str, **options: Any) -> Strategy:
    target = STRATEGIES.get(name)
    if target is None:
        raise StrategyError(f"unknown strategy {name!r}; choose one of {', '.join(STRATEGIES)}")
    module_name, cls_name = target.split(":")
    cls = getattr(importlib.import_module(module_name), cls_name)
    return cls(**options)
