"""Exploration strategies behind one interface (``base.Strategy``), built by name."""

from explore.learner.strategies.base import (
    MAKE_VAE,
    STRATEGIES,
    STRATEGY_SUMMARIES,
    Description,
    Proposal,
    Strategy,
    StrategyError,
    make_strategy,
)

__all__ = [
    "MAKE_VAE",
    "STRATEGIES",
    "STRATEGY_SUMMARIES",
    "Description",
    "Proposal",
    "Strategy",
    "StrategyError",
    "make_strategy",
]
