"""The prior's rule (explore/learner/prior.py) on hand-made records: the nearer of the arm's own
and the prior's entries answers, a prior entry answers once, the arm's reach retires the prior
near it, goals are drawn over the prior's reach, the prior stands for the bootstrap, with
``prior_context`` a prior entry answers only from a context near its own; strategies and records
that cannot take a prior are refused in one line."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pytest

from explore.learner.experience import Observation
from explore.learner.prior import warm_start
from explore.learner.strategies import StrategyError, make_strategy
from explore.rigs.arena import TWIN_ARENA

N_PARAMS = 6


@dataclass
class Rec:
    episode: int
    theta: np.ndarray
    ball: np.ndarray
    context_ball: np.ndarray = field(default_factory=lambda: np.array([0.17, 0.0]))
    goal: np.ndarray = field(default_factory=lambda: np.zeros(0))
    module: int = -1
    kind: str = "random"
    end_effector: np.ndarray = field(default_factory=lambda: np.zeros((1, 3)))
    image: np.ndarray = field(default_factory=lambda: np.zeros((64, 64, 3), np.uint8))


def _at(angle: float, r: float = 0.17) -> np.ndarray:
    return np.array([r * np.cos(angle), r * np.sin(angle)])


def _prior(n: int = 8) -> list[Rec]:
    """Prior episodes that left the ball at n places around the ring, each from the start."""
    return [Rec(i, np.full(N_PARAMS, i / 10), _at(2 * np.pi * i / n)) for i in range(n)]


def _strategy(**options):
    return make_strategy("rge-efr", N_PARAMS, scene=TWIN_ARENA, bootstrap=5, **options)


def _warm(records, **options):
    s = _strategy(**options)
    prior = warm_start(s, lambda: _strategy(**options), records)
    return s, prior


def _goal_at(s, ball: np.ndarray) -> np.ndarray:
    return s.space.outcome(Rec(0, np.zeros(N_PARAMS), ball))


def test_the_prior_answers_once_then_the_arms_own_outcomes(tmp_path):
    s, prior = _warm(_prior(), random_episodes=0.0, sigma=0.0, stall_window=0)
    assert s.bootstrap == 0 and s.phase() == "rge"  # 8 prior episodes >= bootstrap 5
    # goals over the prior's reach: its bounds are the prior's outcomes'
    outcomes = np.array([_goal_at(s, r.ball) for r in _prior()])
    np.testing.assert_allclose(s.low[0], outcomes.min(axis=0))
    np.testing.assert_allclose(s.high[0], outcomes.max(axis=0))
    ctx = Observation(ball=np.array([0.17, 0.0]))
    goal = _goal_at(s, _at(2 * np.pi * 3 / 8))
    theta = s.policy.nearest_theta(0, s._propose_context(ctx), goal)
    np.testing.assert_array_equal(theta, np.full(N_PARAMS, 0.3))  # prior episode 3's
    # the arm played it (exploit) and the ball went elsewhere
    rec = Rec(0, theta, _at(1.0), goal=goal, module=0, kind="exploit")
    answer = prior.before_update(rec)
    assert answer is not None and answer.prior_episode == 3
    np.testing.assert_allclose(answer.prior_ball, _at(2 * np.pi * 3 / 8))
    s.update(rec)
    # the same goal again: episode 3 is out of play; the nearest left is the arm's own or
    # another prior entry, never 3 again
    again = s.policy.nearest_theta(0, s._propose_context(ctx), goal)
    assert not np.array_equal(again, np.full(N_PARAMS, 0.3))
    assert prior.answered == 1 and prior.in_play() == 7
    # the arm's own records never count as seen episodes of the prior's, nor the reverse
    assert s.n_seen == 1


def test_the_arms_own_nearer_outcome_wins_and_its_reach_retires_the_prior():
    s, prior = _warm(_prior())
    own = Rec(0, np.full(N_PARAMS, -0.5), _at(2 * np.pi * 2 / 8 + 0.01))  # by prior entry 2
    assert prior.before_update(own) is None  # a random episode: not the prior's
    s.update(own)
    assert prior.policy.retired_by_reach == 1  # entry 2 was within the reach radius
    ctx = s._propose_context(Observation(ball=np.array([0.17, 0.0])))
    goal = _goal_at(s, _at(2 * np.pi * 2 / 8))
    np.testing.assert_array_equal(s.policy.nearest_theta(0, ctx, goal), own.theta)
    assert prior.policy.prior_answer(0, ctx, goal) == -1


def test_proposals_start_with_goals_and_are_a_function_of_the_state():
    a, _ = _warm(_prior())
    b, _ = _warm(_prior())
    ctx = Observation(ball=np.array([0.17, 0.0]))
    pa = a.propose(ctx, np.random.default_rng(4))
    pb = b.propose(ctx, np.random.default_rng(4))
    assert pa.kind in ("explore", "exploit") and np.array_equal(pa.theta, pb.theta)


def test_what_cannot_take_a_prior_is_refused_in_one_line():
    with pytest.raises(StrategyError, match="has 4 motor parameters, this rig's motor primitive 6"):
        _warm([Rec(0, np.zeros(4), _at(0.0))])
    with pytest.raises(StrategyError, match="random schedule only"):
        _warm(_prior(), schedule="cycle")
    with pytest.raises(StrategyError, match="no goal space"):
        rpe = make_strategy("rpe", N_PARAMS, scene=TWIN_ARENA)
        warm_start(rpe, lambda: rpe, _prior())
    with pytest.raises(StrategyError, match="holds no episode"):
        _warm([])


def test_an_arm_entry_as_near_as_the_prior_s_wins_whatever_the_index_s_schedule():
    # the arm's 64 identical entries fill its k-d tree (8-D: the tree's own distance once met
    # np.linalg.norm's on the prior's side, and an ulp gave the tie to the prior); the prior's
    # entry mirrors them in the first coordinate, so every query with a first coordinate 0
    # is exactly as near to both
    from explore.learner.meta_policy import MetaPolicy
    from explore.learner.prior import WarmPolicy, _ModulePrior

    rng = np.random.default_rng(11)
    own = rng.uniform(-1, 1, 8)
    own[0] = 0.5
    mirror = own.copy()
    mirror[0] = -0.5
    far = mirror - 10 * np.eye(8)[0]  # farther than both from every query; reach radius 0.3
    points = np.stack([mirror, far])
    policy = WarmPolicy(
        MetaPolicy(4, [4], N_PARAMS),
        [_ModulePrior(points, np.zeros((2, N_PARAMS)), np.array([0, 1]))],
    )
    for _ in range(64):
        policy.add(own[:4], [own[4:]], np.ones(N_PARAMS))
    assert policy.indexes[0].outside_tree == 0 and policy.prior[0].alive.all()
    queries = rng.uniform(-1, 1, (1000, 8))
    queries[:, 0] = 0.0
    answers = [policy.prior_answer(0, q[:4], q[4:]) for q in queries]
    assert answers == [-1] * len(queries)  # a tie: the arm's own answers


def _two_scenes() -> list[Rec]:
    """Prior episodes from two scenes: 0-3 with the ball at angle 0, 4-7 with it at 0.6 rad
    (10 cm further along the ring: the twin's ball where the last episode left it), each
    leaving it somewhere on the ring."""
    return [
        Rec(i, np.full(N_PARAMS, i / 10), _at(2 * np.pi * i / 8), context_ball=_at(0.6 * (i > 3)))
        for i in range(8)
    ]


@pytest.mark.parametrize("fraction", [0.1, None])
def test_a_prior_entry_answers_only_from_a_context_near_its_own(fraction):
    options = {} if fraction is None else {"prior_context": fraction}
    s, prior = _warm(_two_scenes(), random_episodes=0.0, sigma=0.0, stall_window=0, **options)
    assert s.settings.prior_context == (0.0 if fraction is None else 0.1)
    # the arm's ball at angle 0, a goal where prior episode 5 (ball at 0.6) left its ball
    ctx = s._propose_context(Observation(ball=_at(0.0)))
    goal = _goal_at(s, _at(2 * np.pi * 5 / 8))
    j = prior.policy.prior_answer(0, ctx, goal)
    source = int(prior.policy.prior[0].source[j])
    if fraction is None:  # by default any context: the nearest in (context, outcome), episode 5
        assert source == 5
    else:  # episode 5 pushed a ball at 0.6: of the scenes like the arm's, the nearest outcome
        assert source in range(4) and source == 3
    # what the proposal played is what the update works out again (rule 2 retires it)
    theta = s.policy.nearest_theta(0, ctx, goal)
    rec = Rec(0, theta, _at(1.0), context_ball=_at(0.0), goal=goal, module=0, kind="exploit")
    answer = prior.before_update(rec)
    assert answer is not None and answer.prior_episode == source
    np.testing.assert_array_equal(theta, np.full(N_PARAMS, source / 10))


def test_with_no_prior_entry_near_the_arms_scene_the_arm_answers_itself():
    s, prior = _warm(
        _two_scenes(), random_episodes=0.0, sigma=0.0, stall_window=0, prior_context=0.1
    )
    # the arm's ball at pi / 2: no prior scene within 0.1 of the contexts' diagonal (but with
    # any context, the nearest prior entry would answer: the arm has no entry yet)
    ctx = s._propose_context(Observation(ball=_at(np.pi / 2)))
    assert prior.policy.prior_answer(0, ctx, _goal_at(s, _at(0.3))) == -1
    _, anywhere = _warm(_two_scenes())
    assert anywhere.policy.prior_answer(0, ctx, _goal_at(s, _at(0.3))) >= 0
    with pytest.raises(StrategyError, match="prior_context"):
        _strategy(prior_context=-0.1)
