"""Exploration strategies behind one interface (``base.Strategy``), built by name."""

from explore.strategies.base import STRATEGIES, Proposal, Strategy, StrategyError, make_strategy

__all__ = ["STRATEGIES", "Proposal", "Strategy", "StrategyError", "make_strategy"]
