"""The strategy interface: what goal exploration (and random exploration) implement.

A strategy proposes motor parameters for the next episode from the context observed at the
rest pose, then learns from the stored record of that episode. Its state must be a
deterministic function of the records it was updated with, so that a resumed run rebuilds it
by replaying the history.

Strategies are built by name from ``registry.STRATEGIES`` (imported lazily). Each declares its
options as a dataclass ``Options`` (``explore.options``): unknown keys and wrong types are
refused in one line with the known options listed. It proposes ``n_params`` motor parameters,
the count of the rig's motor primitive (48 for the Ergo Jr's DMPs, 49 for ArmBalls' RBFs), and
knows the rig's ``scene`` (``explore.learner.scene``: the frame of engineered features, whether
the scene resets between episodes), both given by the rig, never assumed.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from explore.learner.dmp import N_PARAMS
from explore.learner.experience import Experience, Observation
from explore.learner.scene import Scene
from explore.options import OptionsError, parse_options


@dataclass
class Proposal:
    """What to play next.

    Attributes:
        theta: motor parameters, shape (n_params,), in [-1, 1].
        goal: the goal aimed at in the strategy's goal space, shape (g,) (empty for RPE).
        module: goal-space module index (-1 when none).
        kind: "random" (motor babbling), "explore" (goal + noise) or "exploit" (goal, no noise).
    """

    theta: np.ndarray
    goal: np.ndarray = field(default_factory=lambda: np.zeros(0))
    module: int = -1
    kind: str = "random"


class StrategyError(ValueError):
    """Unknown strategy or bad strategy options."""


@dataclass(frozen=True)
class NoOptions:
    """A strategy without options."""


class Strategy(ABC):
    """Base class of exploration strategies.

    Args:
        n_params: motor parameters to propose (the rig's ``motor.n_params``).
        scene: the rig's scene (``explore.rigs.rig.rig_scene``; required: the learner knows no
            rig's).
        name: its name in ``registry.STRATEGIES`` (default: the class's ``name``).
        **options: the strategy's options as given (``self.options``), read into its ``Options``
            dataclass (``self.settings``).
    """

    name: str = "strategy"
    Options: type = NoOptions
    #: whether ``propose`` needs ``context.image`` (a render/frame at the rest pose)
    needs_context_image: bool = False
    #: whether the run is worth starting only where the ball is located (goal exploration: its
    #: goals and its measure are ball positions); a physical rig without an arena calibration
    #: sees none, and ``open_run`` refuses such a run
    needs_ball: bool = False

    def __init__(
        self, n_params: int = N_PARAMS, *, scene: Scene, name: str | None = None, **options: Any
    ) -> None:
        if name is not None:
            self.name = name
        self.options = dict(options)
        try:
            self.settings = parse_options(self.Options, options, f"strategy {self.name!r}")
        except OptionsError as exc:
            raise StrategyError(str(exc)) from None
        self.n_params = int(n_params)
        self.scene = scene

    @classmethod
    def options_for(cls, **params: Any) -> type:
        """The ``Options`` dataclass of this class built with ``params`` (a registry entry's:
        ``registry.StrategyEntry.params``)."""
        return cls.Options

    @abstractmethod
    def propose(self, context: Observation, rng: np.random.Generator) -> Proposal:
        """Motor parameters for the next episode."""

    def update(self, record: Experience) -> None:  # noqa: B027 - optional hook
        """Learn from a finished episode (default: nothing)."""

    def phase(self) -> str:
        """A short label of what the strategy is doing now (for progress displays)."""
        return self.name

    def describe(self, record: Experience) -> Description | None:
        """A finished episode in this strategy's goal space, as ``update`` is about to learn
        from it (call it just before ``update(record)``); None while the strategy has no goal
        space (RPE, an online representation before its training)."""
        return None


@dataclass
class Description:
    """An episode in a goal space (``Strategy.describe``).

    Attributes:
        context: the scene before the move, shape (context_dim,).
        outcome: what the move produced, shape (dim,); NaN where not seen.
        goal: the episode's goal in the whole space, shape (dim,): NaN outside the module it
            was sampled in, all NaN for an episode without a goal (motor babbling).
    """

    context: np.ndarray
    outcome: np.ndarray
    goal: np.ndarray
