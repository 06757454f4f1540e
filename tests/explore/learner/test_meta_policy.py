"""Nearest-neighbour meta-policy: exact 1-NN across tree rebuilds, noise and clipping."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from explore.learner.meta_policy import MetaPolicy, NearestNeighbourIndex
from plumbing.fixed_order import sq_distances


@settings(max_examples=40, deadline=None)
@given(
    n=st.integers(1, 400),
    dim=st.integers(1, 5),
    seed=st.integers(0, 2**31 - 1),
    grid=st.booleans(),
    rebuild_tail=st.sampled_from([1, 7, 40, 1024]),
    tree=st.booleans(),
)
def test_nearest_equals_brute_force_across_rebuilds(n, dim, seed, grid, rebuild_tail, tree):
    rng = np.random.default_rng(seed)
    # grid points make many exact ties: the lowest index must win, as in a brute-force argmin
    pts = rng.integers(-2, 3, (n, dim)).astype(float) if grid else rng.normal(size=(n, dim))
    index = NearestNeighbourIndex(dim, rebuild_tail, tree_max_dim=8 if tree else 0)
    assert index.uses_tree == tree
    for k, p in enumerate(pts):
        index.add(p)
        if k % 17 == 0 or k == n - 1:  # query while the tree is stale and after rebuilds
            for q in rng.normal(size=(3, dim)) * 2:
                sq = sq_distances(pts[: k + 1], q)  # the one distance, brute force
                i, dist = index.nearest(q)
                assert dist == np.sqrt(sq.min())
                assert i == int(np.argmin(sq))


@pytest.mark.parametrize("offset", [0.0, 1e3])
def test_the_high_dimensional_scan_is_exact_with_ties_and_far_from_the_origin(offset):
    # 20-D points take the matrix-vector scan (no tree). A grid of step 0.1 and queries halfway
    # between grid points make many exact ties; an offset of 1e3 makes the norm expansion
    # round them apart, which the exact recheck must undo (lowest index wins, as in argmin)
    rng = np.random.default_rng(3)
    grid = rng.integers(-1, 2, (1500, 20)) * 0.1
    pts = np.concatenate([grid, rng.normal(size=(1500, 20))]) + offset
    index = NearestNeighbourIndex(20)
    assert not index.uses_tree
    for p in pts:
        index.add(p)
    half = rng.integers(-1, 1, (100, 20)) * 0.1 + 0.05 + offset
    for q in np.concatenate([half, pts[rng.integers(0, len(pts), 50)], rng.normal(size=(50, 20))]):
        sq = sq_distances(pts, q)
        i, dist = index.nearest(q)
        assert i == int(np.argmin(sq))
        assert dist == np.sqrt(sq.min())


@pytest.mark.parametrize("rebuild_tail", [1, 2, 7, 64, 1024])
def test_exact_duplicates_in_8_dimensions_all_answer_with_the_earliest(rebuild_tail):
    # 66 identical (context, outcome) points at 8-D (rge-sae with 2 live features, a ball that
    # did not move): the tree's distance and the scan's once differed by an ulp, and episode
    # 64 (past the tree's rebuild at 64) answered a tenth of the goals
    rng = np.random.default_rng(5)
    point = rng.uniform(-1, 1, 8)
    index = NearestNeighbourIndex(8, rebuild_tail)
    assert index.uses_tree
    for _ in range(66):
        index.add(point)
    answers = {index.nearest(q)[0] for q in rng.uniform(-1.5, 1.5, (1000, 8))}
    assert answers == {0}


def test_points_left_outside_the_tree_stay_bounded_as_the_history_grows():
    # the doubling-only schedule left up to half of the points outside the tree
    index = NearestNeighbourIndex(2, rebuild_tail=50)
    worst = 0
    for k, p in enumerate(np.random.default_rng(0).normal(size=(5000, 2))):
        index.add(p)
        if k >= 64:
            worst = max(worst, index.outside_tree)
            assert index.outside_tree < max(50, (k + 1) // 32) + 1
    assert worst > 100  # the n / 32 regime was reached (past the fixed tail of 50)
    assert index.nearest(np.zeros(2))[0] == int(np.argmin(np.linalg.norm(index.points, axis=1)))


def test_index_rejects_bad_points():
    index = NearestNeighbourIndex(2)
    with pytest.raises(ValueError, match="empty"):
        index.nearest(np.zeros(2))
    with pytest.raises(ValueError, match="shape"):
        index.add(np.zeros(3))
    with pytest.raises(ValueError, match="NaN"):
        index.add(np.array([0.0, np.nan]))


def test_meta_policy_returns_the_nearest_parameters_with_noise_and_clipping():
    policy = MetaPolicy(context_dim=1, module_dims=[2, 1], n_params=4)
    thetas = [np.full(4, 0.1), np.full(4, 0.99), np.full(4, -0.5)]
    outcomes = [np.array([0.0, 0.0, 5.0]), np.array([1.0, 1.0, 6.0]), np.array([2.0, 2.0, 7.0])]
    for th, o in zip(thetas, outcomes, strict=True):
        policy.add(np.zeros(1), [o[:2], o[2:]], th)
    policy.add(np.zeros(1), [None, np.array([9.0])], np.full(4, 0.3))  # module 0 saw nothing
    assert policy.size(0) == 3 and policy.size(1) == 4
    rng = np.random.default_rng(0)
    assert np.array_equal(policy.infer(0, np.zeros(1), np.array([0.9, 1.2]), rng, 0.0), thetas[1])
    assert np.array_equal(policy.infer(1, np.zeros(1), np.array([8.8]), rng, 0.0), np.full(4, 0.3))
    noisy = np.array([policy.infer(0, np.zeros(1), np.array([1.0, 1.0]), rng) for _ in range(2000)])
    assert noisy.max() <= 1.0  # clipped at the bound
    assert np.mean(noisy == 1.0) == pytest.approx(0.42, abs=0.05)  # P(0.99 + N(0, .05) > 1)
    below = noisy[noisy < 1.0]
    assert np.std(noisy[:, 0] - 0.99) < 0.05 and below.min() > 0.99 - 6 * 0.05
    around = np.array([policy.infer(0, np.zeros(1), np.zeros(2), rng) for _ in range(2000)])
    assert np.std(around - 0.1) == pytest.approx(0.05, rel=0.05)
    assert np.mean(around) == pytest.approx(0.1, abs=0.005)


def test_spread_ties_pick_among_equally_near_points_by_the_query_and_first_picks_the_earliest():
    first = MetaPolicy(context_dim=0, module_dims=[2], n_params=3)
    spread = MetaPolicy(context_dim=0, module_dims=[2], n_params=3, ties="spread")
    rest = np.array([0.6, 0.6])  # where the ball lies in most episodes: all equally near
    for i in range(40):
        for policy in (first, spread):
            policy.add(np.zeros(0), [rest], np.full(3, i / 100))
    for policy in (first, spread):
        policy.add(np.zeros(0), [np.array([-0.9, -0.9])], np.full(3, 0.99))
    rng = np.random.default_rng(1)
    goals = rng.uniform(0.0, 1.0, (200, 2))  # every one nearer to the rest position
    picked = [spread.nearest_theta(0, np.zeros(0), g)[0] for g in goals]
    assert {first.nearest_theta(0, np.zeros(0), g)[0] for g in goals} == {0.0}
    assert len(set(picked)) >= 35  # spread over the 40 tied episodes
    assert 0.99 not in picked  # never a farther point
    again = [spread.nearest_theta(0, np.zeros(0), g)[0] for g in goals]
    assert picked == again  # a function of the query: a resumed run replays the same
    assert spread.nearest_theta(0, np.zeros(0), np.array([-1.0, -1.0]))[0] == 0.99
    with pytest.raises(ValueError, match="ties"):
        MetaPolicy(0, [2], 3, ties="random")


def test_a_module_is_varied_once_it_has_recorded_two_different_points():
    policy = MetaPolicy(context_dim=1, module_dims=[2, 2], n_params=2)
    for _ in range(5):
        policy.add(np.zeros(1), [np.array([0.6, 0.6]), None], np.zeros(2))
    assert not policy.varied(0) and not policy.varied(1)
    policy.add(np.zeros(1), [np.array([0.6, 0.6]), np.array([0.1, 0.2])], np.zeros(2))
    assert not policy.varied(0) and not policy.varied(1)  # one point each so far
    policy.add(np.ones(1), [np.array([0.6, 0.6]), np.array([0.1, 0.2])], np.zeros(2))
    assert policy.varied(0) and policy.varied(1)  # the context differs: another point


def test_a_weighted_context_replays_an_episode_played_from_a_nearby_context():
    # two stored episodes: one from the current context (c = 0) that moved its outcome part
    # of the way to the goal, one from a context 1 away that reached the goal exactly
    here, there = np.full(3, 0.1), np.full(3, 0.9)
    joint = MetaPolicy(context_dim=1, module_dims=[1], n_params=3)
    weighted = MetaPolicy(context_dim=1, module_dims=[1], n_params=3, context_weight=3.0)
    for policy in (joint, weighted):
        policy.add(np.zeros(1), [np.array([0.5])], here)
        policy.add(np.ones(1), [np.array([2.0])], there)
    ctx, goal = np.zeros(1), np.array([2.0])
    # joint search: |(0, 2) - (1, 2)| = 1 < |(0, 2) - (0, 0.5)| = 1.5, the far context wins
    assert np.array_equal(joint.nearest_theta(0, ctx, goal), there)
    # context weighted by 3: the far episode is 3 away, the near one still 1.5
    assert np.array_equal(weighted.nearest_theta(0, ctx, goal), here)
    # from the far context, the weighted policy replays the far episode again
    assert np.array_equal(weighted.nearest_theta(0, np.ones(1), goal), there)
    with pytest.raises(ValueError, match="context_weight"):
        MetaPolicy(1, [1], 3, context_weight=0.0)
