"""Exploration strategies behind one interface (``base.Strategy``), built by name from their
registry (``registry.STRATEGIES``)."""

from explore.learner.strategies.base import (
    Description,
    Proposal,
    Strategy,
    StrategyError,
)
from explore.learner.strategies.registry import (
    STRATEGIES,
    Model,
    StrategyEntry,
    make_strategy,
)

__all__ = [
    "STRATEGIES",
    "Description",
    "Model",
    "Proposal",
    "Strategy",
    "StrategyEntry",
    "StrategyError",
    "make_strategy",
]
