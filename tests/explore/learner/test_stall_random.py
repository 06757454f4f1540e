"""Option ``stall_window``: more random-parameter episodes while the outcome stays put."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from explore.learner.experience import Observation
from explore.learner.strategies import make_strategy
from explore.rigs.arena import TWIN_ARENA

BOOT, WINDOW = 6, 8


@dataclass
class Episode:
    """The fields of an ``Experience`` that an engineered strategy reads; positions in m."""

    episode: int
    context_ball: np.ndarray
    ball: np.ndarray
    kind: str = "random"
    module: int = -1
    theta: np.ndarray = field(default_factory=lambda: np.zeros(48))
    goal: np.ndarray = field(default_factory=lambda: np.zeros(0))
    end_effector: np.ndarray = field(default_factory=lambda: np.full((1, 3), np.nan))
    image: np.ndarray = field(default_factory=lambda: np.zeros((1, 1, 3), np.uint8))


def on_ring(angle: float, r: float = 0.15) -> np.ndarray:
    return np.array([r * np.cos(angle), r * np.sin(angle)])


def kinds(strategy, ball: np.ndarray, n: int = 200) -> list[str]:
    ctx = Observation(ball=ball)
    return [strategy.propose(ctx, np.random.default_rng([7, k])).kind for k in range(n)]


def test_random_share_rises_after_a_window_of_unchanged_outcomes_and_falls_back():
    rng = np.random.default_rng(3)
    angles = rng.uniform(-np.pi, np.pi, BOOT + 1)
    moving = [
        Episode(i, on_ring(angles[i]), on_ring(angles[i + 1]), theta=rng.uniform(-1, 1, 48))
        for i in range(BOOT)
    ]
    ball = on_ring(angles[BOOT])
    still = [
        Episode(BOOT + i, ball, ball.copy(), "explore", 0, rng.uniform(-1, 1, 48), np.zeros(3))
        for i in range(WINDOW)
    ]
    with_option = make_strategy("rge-efr", scene=TWIN_ARENA, bootstrap=BOOT, stall_window=WINDOW)
    without = make_strategy("rge-efr", scene=TWIN_ARENA, bootstrap=BOOT, stall_window=0)
    for s in (with_option, without):
        for r in moving + still[:-1]:
            s.update(r)
    share = with_option.settings.random_episodes
    assert with_option.random_share() == share  # one unchanged episode short of the window
    n_random = kinds(with_option, ball).count("random")
    assert 0 < n_random < 0.3 * 200
    for s in (with_option, without):
        s.update(still[-1])
    assert with_option.random_share() == 1.0  # the default stall_random
    assert set(kinds(with_option, ball)) == {"random"}
    assert without.random_share() == share  # without the option nothing changes
    assert "explore" in kinds(without, ball)
    # an episode that moves the ball again: back to the usual share
    moved = Episode(BOOT + WINDOW, ball, on_ring(angles[BOOT] + 0.5), "random")
    with_option.update(moved)
    assert with_option.random_share() == share
    assert "explore" in kinds(with_option, moved.ball)


def test_a_stall_share_is_an_option_with_checked_values():
    import pytest

    from explore.learner.strategies import StrategyError

    s = make_strategy("rge-efr", scene=TWIN_ARENA, stall_window=5, stall_random=0.5)
    assert (s.stall_window, s.stall_random) == (5, 0.5)
    with pytest.raises(StrategyError, match="stall_random must be a probability"):
        make_strategy("rge-efr", scene=TWIN_ARENA, stall_window=5, stall_random=2)
    with pytest.raises(StrategyError, match="stall_window must be >= 0"):
        make_strategy("rge-efr", scene=TWIN_ARENA, stall_window=-1)
    with pytest.raises(StrategyError, match="context_weight must be > 0"):
        make_strategy("rge-efr", scene=TWIN_ARENA, context_weight=0.0)


def test_on_a_scene_reset_before_every_episode_the_stall_option_never_acts():
    from explore.rigs.armballs import ARM_BALLS_SQUARE

    s = make_strategy("rge-efr", scene=ARM_BALLS_SQUARE, bootstrap=BOOT, stall_window=2)
    ball = np.array([0.3, -0.2])  # in reach units; the ball never moves
    for i in range(BOOT + 5):
        s.update(Episode(i, ball, ball.copy()))
    assert s.still == 0 and s.random_share() == s.settings.random_episodes
