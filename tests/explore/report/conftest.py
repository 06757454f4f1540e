"""Fixtures shared by the report's tests."""

from __future__ import annotations

from pathlib import Path

import pytest


@pytest.fixture(scope="module")
def goal_run(tmp_path_factory) -> Path:
    """A goal-exploration run on the twin: 3 random episodes, then 4 with goals."""
    from explore.runs.config import RunConfig, StrategyConfig
    from explore.runs.open_run import open_run

    out = tmp_path_factory.mktemp("goal") / "rge-efr-s1"
    strategy = StrategyConfig("rge-efr", {"bootstrap": 3, "random_episodes": 0})
    with open_run(out, RunConfig(strategy=strategy, seed=1, episodes=7), mode="new") as run:
        run.explore()
    return out
