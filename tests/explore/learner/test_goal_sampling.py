"""Goal selection (option ``goal_sampling``): the density sampler picks goals where reached
outcomes are sparse, its guard drops goals it missed, runs are deterministic per seed and a
resumed run replays to the same history, on every goal space; bad values are one line."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from explore.campaigns.trial import Trial, run_trial
from explore.learner.goal_sampling import (
    GOAL_MISSES,
    N_CANDIDATES,
    GoalSampler,
    frontier_step,
    kernel_log_density,
    scott_bandwidth,
)
from explore.learner.strategies import StrategyError, make_strategy
from explore.learner.strategies.registry import preset_options
from explore.rigs.arena import TWIN_ARENA
from explore.runs.store import RunStore


def sampler_over(points: np.ndarray, mode: str = "density") -> GoalSampler:
    s = GoalSampler(mode, [points.shape[1]])
    lo, hi = points.min(0), points.max(0)  # once: over 20000 points, per point is seconds
    for p in points:
        s.learn([p], -1, None, lo, hi)
    return s


def test_kernel_density_is_the_gaussian_sum_and_scott_the_rule():
    rng = np.random.default_rng(0)
    q, r, h = rng.normal(size=(7, 3)), rng.normal(size=(40, 3)), np.array([0.3, 0.5, 0.2])
    direct = np.log(np.exp(-0.5 * (((q[:, None] - r[None]) / h) ** 2).sum(-1)).sum(1))
    assert np.allclose(kernel_log_density(q, r, h), direct)
    u = rng.uniform(size=(500, 3))
    assert np.allclose(scott_bandwidth(u), 500 ** (-1 / 7) * u.std(0))
    assert np.all(scott_bandwidth(np.zeros((5, 2))) > 0)  # never zero


@settings(max_examples=40, deadline=None)
@given(
    centre=st.tuples(st.floats(-0.5, 0.5), st.floats(-0.5, 0.5)),
    n_dense=st.integers(20, 80),
    n_sparse=st.integers(1, 4),
    seed=st.integers(0, 2**31 - 1),
)
def test_density_picks_a_goal_where_reached_outcomes_are_sparse(centre, n_dense, n_sparse, seed):
    # a tight cluster of reached outcomes and a few lone ones far from it (all candidates:
    # fewer than N_CANDIDATES outcomes): the goal is one of the lone ones
    rng = np.random.default_rng(seed)
    dense = np.asarray(centre) + rng.normal(0.0, 0.02, (n_dense, 2))
    angles = rng.uniform(0, 2 * np.pi, n_sparse)
    sparse = np.asarray(centre) + np.c_[np.cos(angles), np.sin(angles)] * rng.uniform(
        0.6, 1.0, (n_sparse, 1)
    )
    points = rng.permutation(np.vstack([dense, sparse]))
    assert len(points) <= N_CANDIDATES
    s = sampler_over(points)
    goal = s.goal(0, np.random.default_rng(seed), points.min(0), points.max(0))
    assert goal is not None
    assert any(np.array_equal(goal, p) for p in sparse)
    # a uniform draw in the bounds mostly does not: the sparse points are few
    near_dense = np.linalg.norm(dense - goal, axis=1).min()
    assert near_dense > 0.3


def test_density_prefers_sparse_regions_among_many_outcomes():
    # 20000 outcomes, 2% of them spread over the box, the rest in one corner: candidates and
    # the reference are subsampled, and the goals still come from the sparse part
    rng = np.random.default_rng(1)
    pts = np.vstack([rng.normal(-0.8, 0.03, (19600, 2)), rng.uniform(-1, 1, (400, 2))])
    s = sampler_over(rng.permutation(pts))
    goals = np.array([s.goal(0, np.random.default_rng([2, k]), -np.ones(2), np.ones(2))
                      for k in range(50)])  # fmt: skip
    far = np.linalg.norm(goals + 0.8, axis=1) > 0.3
    assert far.mean() > 0.8  # against 2% of the outcomes drawn uniformly


def test_with_a_context_the_goal_was_reached_from_a_context_near_it():
    # outcomes reached from two contexts: from A a cluster and a few spread ones, from B only
    # spread ones (sparser still). From A, the goal is one of A's spread outcomes, not B's
    rng = np.random.default_rng(3)
    from_a = np.vstack([rng.normal(0.0, 0.02, (280, 2)), rng.uniform(-1, 1, (20, 2))])
    from_b = rng.uniform(-1, 1, (300, 2)) * 3
    a, b = np.array([0.0, 0.0, 1.0]), np.array([1.0, 1.0, 0.0])
    s = GoalSampler("density", [2], context_dim=3)
    lo, hi = np.full(2, -3.0), np.full(2, 3.0)
    for o, c in [(o, a) for o in from_a] + [(o, b) for o in from_b]:
        s.learn([o], -1, None, lo, hi, c)
    for k in range(20):
        goal = s.goal(0, np.random.default_rng(k), lo, hi, a + 0.01)
        assert any(np.array_equal(goal, o) for o in from_a[280:])
    # without the context, B's sparser outcomes win
    blind = [s.goal(0, np.random.default_rng(k), lo, hi) for k in range(20)]
    assert sum(any(np.array_equal(g, o) for o in from_b) for g in blind) >= 15


def test_sparse_takes_the_least_dense_draw_near_the_reached_set():
    rng = np.random.default_rng(4)
    pts = np.vstack([rng.normal(0.0, 0.05, (200, 2)), rng.uniform(-1, 1, (40, 2))])
    s = sampler_over(pts, "sparse")
    lo, hi = pts.min(0), pts.max(0)
    in_cluster, in_a_hole, far_out = [0.0, 0.0], [0.7, -0.7], [30.0, 30.0]
    drawn = np.array([in_cluster, in_a_hole, far_out])
    goal = s.goal(0, np.random.default_rng(0), lo, hi, drawn=drawn)
    assert np.array_equal(goal, in_a_hole)  # far_out is sparser still, but out of reach
    alone = s.goal(0, np.random.default_rng(0), lo, hi, drawn=np.array([far_out, far_out]))
    assert np.array_equal(alone, far_out)  # nothing near: the first draw, as uniform


def test_frontier_steps_one_bandwidth_out_of_the_reached_set():
    ref = np.array([[0.0, 0.0], [0.1, 0.0], [0.2, 0.0]])
    h = np.array([0.1, 0.1])
    g = frontier_step(np.array([0.2, 0.0]), ref, h)
    assert np.allclose(g, [0.3, 0.0])  # away from the others, one bandwidth
    lone = frontier_step(np.array([0.5, 0.5]), np.array([[0.5, 0.5]]), h)
    assert np.array_equal(lone, [0.5, 0.5])


def test_the_guard_drops_an_outcome_missed_goal_misses_times():
    pts = np.vstack([np.zeros((30, 2)), [[1.0, 1.0]]])
    s = sampler_over(pts)
    lo, hi = pts.min(0), pts.max(0)
    lone = np.array([1.0, 1.0])
    assert np.array_equal(s.goal(0, np.random.default_rng(0), lo, hi), lone)
    for k in range(GOAL_MISSES):
        # a goal episode aimed at the lone outcome and ended at the cluster: a miss
        s.learn([np.zeros(2)], 0, lone, lo, hi)
        chosen = s.goal(0, np.random.default_rng(k), lo, hi)
        assert np.array_equal(chosen, lone) == (k < GOAL_MISSES - 1)
    # a hit is not a miss
    s2 = sampler_over(pts)
    for _ in range(GOAL_MISSES):
        s2.learn([lone + 0.01], 0, lone, lo, hi)
    assert s2.stores[0].misses.max() == 0
    # goal_misses=0: no guard
    s3 = GoalSampler("density", [2], goal_misses=0)
    for p in pts:
        s3.learn([p], -1, None, lo, hi)
    for _ in range(5):
        s3.learn([np.zeros(2)], 0, lone, lo, hi)
    assert np.array_equal(s3.goal(0, np.random.default_rng(0), lo, hi), lone)


def test_bad_goal_sampling_values_are_one_line_errors():
    expected = (
        r"option goal_sampling must be one of 'uniform', 'density', 'frontier', 'sparse', got "
        r"'dense' "
        r"\(did you mean 'density'\?\)$"
    )
    with pytest.raises(StrategyError, match=expected):
        make_strategy("rge-efr", scene=TWIN_ARENA, goal_sampling="dense")
    with pytest.raises(StrategyError, match=r"option goal_misses must be >= 0, got -1$"):
        make_strategy("mge-efr", scene=TWIN_ARENA, goal_misses=-1)
    with pytest.raises(StrategyError, match="option goal_misses must be an integer"):
        make_strategy("rge-efr", scene=TWIN_ARENA, goal_misses=1.5)


# ---- runs: every goal space, deterministic, resumed = uninterrupted ---------------------------
A2B = {"name": "arm2balls", "rig_id": "twin", "options": {}}


@pytest.fixture(scope="module")
def models(tmp_path_factory) -> dict[str, str]:
    """An untrained VAE and spatial autoencoder: enough to give a latent and an image-position
    goal space (what they encode is not what is tested)."""
    from testkit.untrained_models import save_untrained_models

    return save_untrained_models(tmp_path_factory.mktemp("models"))


def a2b_options(strategy: str, sampling: str, models: dict[str, str]) -> dict:
    opts = preset_options("corl2018", strategy)
    opts.update(bootstrap=20, goal_sampling=sampling)
    if "vae" in strategy:
        opts["vae"] = models["vae"]
    if "sae" in strategy:
        opts["sae"] = models["sae"]
    return opts


def play(out: Path, strategy: str, opts: dict, episodes: int, rig: dict | None = A2B) -> list:
    run_trial(Trial.of(str(out), strategy, 4, episodes, opts, rig))
    return RunStore.open(out).records


def same(a: list, b: list) -> bool:
    return len(a) == len(b) and all(x.equals(y) for x, y in zip(a, b, strict=True))


@pytest.mark.parametrize("sampling", ["density", "frontier", "sparse"])
@pytest.mark.parametrize("strategy", ["rge-efr", "mge-efr", "rge-vae", "mge-sae"])
def test_runs_are_deterministic_and_resume_to_the_same_history(
    strategy, sampling, models, tmp_path
):
    opts = a2b_options(strategy, sampling, models)
    whole = play(tmp_path / "whole", strategy, opts, 90)
    again = play(tmp_path / "again", strategy, opts, 90)
    assert same(whole, again)
    play(tmp_path / "resumed", strategy, opts, 55)
    resumed = play(tmp_path / "resumed", strategy, opts, 90)
    assert same(whole, resumed)
    # the sampler chose the goals: not what uniform goals give on the same seed
    uniform = play(tmp_path / "uniform", strategy, a2b_options(strategy, "uniform", models), 90)
    assert not same(whole, uniform)
    assert (
        RunStore.read_meta(tmp_path / "whole")["config"]["strategy"]["options"]["goal_sampling"]
        == sampling
    )


def test_density_goals_are_reached_outcomes_on_the_twin(tmp_path):
    # the twin, the ball left in place (a context): every density goal is an outcome the run
    # had reached before it (ball features), and the run resumes to the same history
    opts = {"bootstrap": 30, "goal_sampling": "density"}
    whole = play(tmp_path / "whole", "rge-efr", opts, 60, rig=None)
    play(tmp_path / "resumed", "rge-efr", opts, 45, rig=None)
    assert same(whole, play(tmp_path / "resumed", "rge-efr", opts, 60, rig=None))
    s = make_strategy("rge-efr", scene=TWIN_ARENA, **opts)
    aimed = 0
    for r in whole:
        if r.kind in ("explore", "exploit"):
            reached = s.sampler.stores[0].points[: s.sampler.stores[0].n]
            assert np.any(np.all(reached == r.goal, axis=1))
            aimed += 1
        s.update(r)
    assert aimed > 10
