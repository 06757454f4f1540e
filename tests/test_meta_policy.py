"""Nearest-neighbour meta-policy: exact 1-NN across tree rebuilds, noise and clipping."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from explore.meta_policy import MetaPolicy, NearestNeighbourIndex


@settings(max_examples=40, deadline=None)
@given(
    n=st.integers(1, 300),
    dim=st.integers(1, 5),
    seed=st.integers(0, 2**31 - 1),
    grid=st.booleans(),
)
def test_nearest_equals_brute_force_across_rebuilds(n, dim, seed, grid):
    rng = np.random.default_rng(seed)
    # grid points make many exact ties: the lowest index must win, as in a brute-force argmin
    pts = rng.integers(-2, 3, (n, dim)).astype(float) if grid else rng.normal(size=(n, dim))
    index = NearestNeighbourIndex(dim)
    for k, p in enumerate(pts):
        index.add(p)
        if k % 17 == 0 or k == n - 1:  # query while the tree is stale and after rebuilds
            for q in rng.normal(size=(3, dim)) * 2:
                d = np.linalg.norm(pts[: k + 1] - q, axis=1)
                i, dist = index.nearest(q)
                assert dist == pytest.approx(d.min(), abs=1e-12)
                assert i == int(np.argmin(d))


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
