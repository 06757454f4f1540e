"""Engineered goal-space features and MGE module choice by interest."""

from __future__ import annotations

import numpy as np
import pytest

from explore.learner.goal_spaces import (
    EngineeredGoalSpace,
    kl_ranked_modules,
    ring_polar_features,
    wrap_safe_features,
)
from explore.learner.interest import ModuleInterest
from explore.rigs.arena import R_MAX, R_MIN, TWIN_ARENA
from explore.rigs.armballs import ARM_2_BALLS_SQUARE

RING = (R_MIN, R_MAX)  # the twin's ring, m


def test_ring_polar_features_normalise_the_ring_to_minus_one_one():
    xy = np.array([[R_MIN, 0.0], [0.0, R_MAX], [-(R_MIN + R_MAX) / 2, 1e-12], [0.0, -R_MIN]])
    f = ring_polar_features(xy, RING)
    np.testing.assert_allclose(f[:, 0], [-1, 1, 0, -1], atol=1e-9)
    np.testing.assert_allclose(f[:, 1], [0, 0.5, 1, -0.5], atol=1e-9)
    assert np.all(np.abs(f) <= 1 + 1e-9)


def test_wrap_safe_features_are_continuous_across_plus_minus_pi():
    eps = 1e-6
    r = 0.15
    above = np.array([r * np.cos(np.pi - eps), r * np.sin(np.pi - eps)])
    below = np.array([r * np.cos(-np.pi + eps), r * np.sin(-np.pi + eps)])
    # the paper's polar angle jumps by ~2 across the negative x axis; the wrap-safe form does not
    assert abs(ring_polar_features(above, RING)[1] - ring_polar_features(below, RING)[1]) > 1.9
    assert np.linalg.norm(wrap_safe_features(above, RING) - wrap_safe_features(below, RING)) < 1e-5
    # and it is continuous all around: small steps in angle give small steps in features
    t = np.linspace(-np.pi, np.pi, 721)
    f = wrap_safe_features(np.stack([r * np.cos(t), r * np.sin(t)], axis=1), RING)
    assert np.max(np.linalg.norm(np.diff(f, axis=0), axis=1)) < 0.01


class _Rec:
    def __init__(self, ball, context_ball, tip=(0.1, 0.0)):
        self.ball = np.asarray(ball, float)
        self.context_ball = np.asarray(context_ball, float)
        self.end_effector = np.array([[0.0, 0.0, 0.0], [*tip, 0.05]])


def test_engineered_space_outcomes_contexts_and_modules():
    space = EngineeredGoalSpace("wrap-safe", hand_module=True, scene=TWIN_ARENA)
    rec = _Rec([0.15, 0.0], [0.0, 0.15], tip=(0.15, -0.3))
    o = space.outcome(rec)
    np.testing.assert_allclose(o, [0, 1, 0, 0.5, -1], atol=1e-12)
    np.testing.assert_allclose(space.context(rec), [0, 0, 1], atol=1e-12)
    parts = space.module_outcomes(o)
    assert [len(p) for p in parts] == [3, 2]
    assert space.outcome(_Rec([np.nan, np.nan], [0.15, 0])) is None
    rec_no_tip = _Rec([0.15, 0.0], [0.15, 0.0], tip=(np.nan, np.nan))
    assert space.module_outcomes(space.outcome(rec_no_tip))[1] is None
    with pytest.raises(ValueError, match="unknown polar form"):
        EngineeredGoalSpace("spherical", scene=TWIN_ARENA)


def test_engineered_forms_follow_the_rig_s_scene():
    # ArmBalls: the balls' positions themselves, (x, y) in its square [-1, 1]^2
    space = EngineeredGoalSpace(None, distractor=True, scene=ARM_2_BALLS_SQUARE)
    assert space.form == "cartesian" and space.dim == 4
    rec = _Rec([0.6, -0.2], [0.6, 0.6])
    rec.distractor, rec.context_distractor = np.array([0.7, -0.45]), np.array([0.7, -0.45])
    np.testing.assert_allclose(space.outcome(rec), [0.6, -0.2, 0.7, -0.45])
    with pytest.raises(ValueError, match="not defined on the Arm-2-Balls square"):
        EngineeredGoalSpace("polar", scene=ARM_2_BALLS_SQUARE)
    # the twin: cartesian over its arena's square, wrap-safe by default
    twin = EngineeredGoalSpace("cartesian", scene=TWIN_ARENA)
    np.testing.assert_allclose(twin.outcome(_Rec([0.1, -0.2], [0, 0])), [0.5, -1.0])
    assert EngineeredGoalSpace(scene=TWIN_ARENA).form == "wrap-safe"


def test_latent_modules_are_pairs_ranked_by_kl():
    kl = [0.1, 5.0, 0.2, 3.0, 0.0, 4.0, 0.3, 2.0, 0.05, 1.0]
    mods = kl_ranked_modules(kl)
    assert len(mods) == 5
    assert [list(m) for m in mods[:2]] == [[1, 5], [3, 7]]
    assert sorted(np.concatenate(mods).tolist()) == list(range(10))


def test_module_choice_follows_interest_with_a_random_floor():
    mi = ModuleInterest([2, 2, 2, 2], random_choice=0.1)
    rng = np.random.default_rng(0)
    # no interest yet: uniform
    np.testing.assert_allclose(mi.probabilities(), 0.25)
    # module 0 makes progress, module 1 a little, 2 and 3 none
    for k, c_new in ((0, 0.0), (1, -0.5), (2, -1.0), (3, -1.0)):
        mi.update(k, np.zeros(2), np.full(2, 1.0), exploit=False, scale=2**0.5)
        mi.update(k, np.zeros(2), np.zeros(2) if c_new == 0 else np.full(2, -c_new), True, 2**0.5)
    interest = mi.interests()
    assert interest[0] == pytest.approx(1.0) and interest[1] == pytest.approx(0.5)
    assert interest[2] == 0 and interest[3] == 0
    expected = 0.1 / 4 + 0.9 * interest / interest.sum()
    np.testing.assert_allclose(mi.probabilities(), expected)
    n = 20000
    counts = np.bincount([mi.choose(rng) for _ in range(n)], minlength=4) / n
    sd = np.sqrt(expected * (1 - expected) / n)
    assert np.all(np.abs(counts - expected) < 5 * sd)
    assert counts[2] > 0.02 and counts[3] > 0.02  # the 10% random floor (2.5% each)


def test_competence_progress_uses_the_nearest_previous_goal():
    mi = ModuleInterest([1], window=3)
    assert mi.update(0, np.array([0.0]), np.array([1.0]), exploit=True, scale=1.0) == 0.0
    mi.update(0, np.array([5.0]), np.array([5.0]), exploit=False, scale=1.0)
    # nearest previous goal to 0.2 is 0.0, which reached 1.0: c_old = -0.8; now reached 0.2
    assert mi.update(0, np.array([0.2]), np.array([0.2]), True, 1.0) == pytest.approx(0.8)
    assert mi.update(0, np.array([0.2]), None, True, 1.0) == pytest.approx(-1.0)
    assert mi.interests()[0] == pytest.approx(abs(0.0 + 0.8 - 1.0) / 3)


def test_the_original_interest_is_an_exponential_average_of_distance_progress():
    # interest_model.py of the CoRL 2018 campaign: c = -min(d, 2), p += (progress - p) / w from
    # p = 1e-5, interest |p|; goals compared with the previous goals' outcomes
    mi = ModuleInterest([2, 2], window=4, average="exponential", competence="distance")
    np.testing.assert_allclose(mi.interests(), [1e-5, 1e-5])  # uniform choice at first
    g = np.array([0.0, 0.0])
    assert mi.update(0, g, np.array([3.0, 0.0]), exploit=True, scale=99.0) == 0.0  # first goal
    p = 1e-5 + (0.0 - 1e-5) / 4
    # nearest previous goal is g, which reached distance 3 (capped at 2): progress -0.5 + 2
    assert mi.update(0, g, np.array([0.0, 0.5]), True, 99.0) == pytest.approx(1.5)
    p += (1.5 - p) / 4
    assert mi.interests()[0] == pytest.approx(abs(p)) and mi.interests()[1] == 1e-5
    # not remembered: a later goal cannot compare with it
    mi.update(1, g, np.array([0.0, 0.0]), exploit=True, scale=1.0, remember=False)
    assert mi.goals[1] == []
    assert mi.competence(g, None, 1.0) == -2.0


def _share_of_the_silent_module(start: float, exploits: int, seed: int) -> float:
    """Module 0's progress is noise (its outcome a random walk, Arm-2-Balls' distractor),
    module 1 earns none (its outcome never moves); each exploit goes to the module chosen.
    Returns module 1's choice probability after ``exploits`` exploits."""
    mi = ModuleInterest([2, 2], window=1000, average="exponential", competence="distance",
                        start=start)  # fmt: skip
    rng = np.random.default_rng(seed)
    walk = np.zeros(2)
    for _ in range(exploits):
        k = mi.choose(rng)
        goal = rng.uniform(-1, 1, 2)
        if k == 0:
            walk = np.clip(walk + rng.normal(0, 0.3, 2), -1, 1)
            mi.update(0, goal, walk.copy(), exploit=True, scale=1.0)
        else:
            mi.update(1, goal, np.array([0.6, 0.6]), exploit=True, scale=1.0)
    return float(mi.probabilities()[1])


def test_a_larger_interest_start_keeps_a_silent_module_in_the_race_longer():
    # from the original's 1e-5, a module whose progress is noise takes nearly every choice
    # within 200 exploits; from 0.01, the silent module keeps a large share for as long
    early = [_share_of_the_silent_module(1e-5, 200, seed) for seed in range(8)]
    kept = [_share_of_the_silent_module(0.01, 200, seed) for seed in range(8)]
    assert np.median(early) < 0.15, early
    assert min(kept) > 0.25, kept
    with pytest.raises(ValueError, match="interest start"):
        ModuleInterest([2], start=-1.0)
    from explore.learner.strategies import make_strategy

    s = make_strategy("mge-efr", n_params=49, scene=ARM_2_BALLS_SQUARE, interest="exponential",
                      interest_start=0.01, distractor=None)  # fmt: skip
    assert s.interest.interests().tolist() == [0.01, 0.01, 0.01]  # ball, distractor, hand
    with pytest.raises(ValueError, match='interest_start acts only with interest="exponential"'):
        make_strategy("mge-efr", n_params=49, scene=ARM_2_BALLS_SQUARE, interest_start=0.01)


def test_goal_sampling_in_the_fixed_box_and_the_latent_prior():
    from explore.learner.strategies import make_strategy

    rng = np.random.default_rng(0)
    s = make_strategy("mge-efr", n_params=49, scene=ARM_2_BALLS_SQUARE, goals="box",
                      distractor=None, hand_module=False)  # fmt: skip
    assert [len(m) for m in s.space.modules] == [2, 2]  # the scene's distractor joins
    goals = np.array([s.sample_goal(0, rng) for _ in range(2000)])
    assert goals.min() >= -1 and goals.max() <= 1 and goals.min() < -0.99 and goals.max() > 0.99
    s = make_strategy("rge-efr", scene=TWIN_ARENA, goals="normal")
    goals = np.array([s.sample_goal(0, rng) for _ in range(20000)])
    assert np.abs(goals).max() == pytest.approx(2.5)  # clipped N(0, 1)
