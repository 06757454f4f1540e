"""An episode's outcome in the coordinates of its goal: the goal space of a strategy (running,
or rebuilt from a run's config) restricted to the module the episode's goal was sampled in.

Used to show goals against what was reached (the rerun recorder's ``goal/*`` entities, the
report's goals figure, the inverse-model diagnosis).
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Any

import numpy as np

from explore.learner.experience import Experience
from explore.learner.scene import Scene

log = logging.getLogger(__name__)


OutcomeOf = Callable[[Experience], "np.ndarray | None"]


def strategy_outcome_of(strategy: Any) -> OutcomeOf | None:
    """The map record -> outcome in ``strategy``'s goal space, restricted to the module the
    record's goal was sampled in (``record.module``), shape (len(module),) like ``record.goal``.

    The map reads ``strategy.space`` at each call (an online space appears during the run and
    is refit: the outcome is then in the space as it is after the strategy's ``update``). It
    returns None for records without a module (random episodes) or an outcome (ball not seen,
    no space yet). Returns None when the strategy has no goal space (RPE).
    """
    if not hasattr(strategy, "space"):
        return None

    def outcome_of(rec: Experience) -> np.ndarray | None:
        space = strategy.space
        if space is None or rec.module < 0 or rec.module >= len(space.modules):
            return None
        o = space.outcome(rec)
        if o is None:
            return None
        return np.asarray(o, dtype=float)[space.modules[rec.module]]

    return outcome_of


def goal_outcome_of(
    strategy_config: dict[str, Any], scene: Scene, load_models: bool = False
) -> OutcomeOf | None:
    """``strategy_outcome_of`` for a run's strategy built from its config (``run.json``'s
    ``config["strategy"]``: name and options) on its rig's ``scene`` (``explore.rigs.rig.
    rig_scene``), without the running strategy.

    Engineered goal spaces (rge-efr, mge-efr) are functions of the record: always built (cheap).
    Learned ones (VAE latents) are built only with ``load_models`` (loads the model, and every
    call encodes the record's image again); an online space (rge-online) does not exist before
    its strategy has seen the run, so it gives None, as does RPE or a strategy that cannot be
    built (unknown name, missing model).
    """
    from explore.learner.strategies import STRATEGIES, StrategyError, make_strategy

    name = str(strategy_config.get("name", ""))
    options = dict(strategy_config.get("options", {}))
    entry = STRATEGIES.get(name)
    if entry is None or not entry.goal_exploration:
        return None
    if not load_models and not entry.engineered:
        return None
    try:
        strategy = make_strategy(name, scene=scene, **options)
    except (StrategyError, OSError, ValueError) as exc:
        log.info("no goal-space outcomes for %s: %s", name, exc)
        return None
    if getattr(strategy, "space", None) is None:
        return None
    return strategy_outcome_of(strategy)
