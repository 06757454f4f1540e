"""Goal exploration on the twin: RGE-EFR runs, and a resumed run replays to the same history."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from explore.campaigns.trial import run_one
from explore.learner.experience import Observation
from explore.learner.strategies import StrategyError, make_strategy
from explore.rigs.arena import TWIN_ARENA
from explore.runs.store import RunStore

N, BOOT = 150, 50


@pytest.fixture(scope="module")
def reference(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("rge") / "run"
    run_one(str(out), "rge-efr", {"bootstrap": BOOT}, 5, N, False)
    return out


def test_rge_efr_bootstraps_then_aims_at_goals(reference):
    recs = RunStore.open(reference).records
    assert len(recs) == N
    assert all(r.kind == "random" and len(r.goal) == 0 for r in recs[:BOOT])
    later = recs[BOOT:]
    goal_directed = [r for r in later if r.kind != "random"]
    assert all(
        r.kind == "explore" and r.module == 0 and r.goal.shape == (3,) for r in goal_directed
    )
    # the rig's default share of random babbling episodes after the bootstrap (10%), out of
    # the episodes not in a stall (after 10 that left the ball still every episode is random:
    # how many there are is the twin's trajectory, which differs between CPUs)
    rebuilt = make_strategy("rge-efr", scene=TWIN_ARENA, bootstrap=BOOT)
    stalled = []
    for r in recs:
        stalled.append(rebuilt.random_share() == 1)
        rebuilt.update(r)
    free = [r for r, s in zip(recs[BOOT:], stalled[BOOT:], strict=True) if not s]
    assert len(free) >= 0.5 * len(later)
    assert 0 < sum(r.kind == "random" for r in free) < 0.3 * len(free)
    assert all(np.all(np.abs(r.theta) <= 1) for r in recs)
    # goals lie within the bounds of the outcomes seen before them
    seen = np.array([[np.hypot(*r.ball[:2])] for r in recs[:BOOT]])
    r_n = (seen - 0.15) / 0.02
    assert r_n.min() - 1e-9 <= goal_directed[0].goal[0] <= r_n.max() + 1e-9


def test_resumed_goal_exploration_replays_to_the_same_history(reference, tmp_path):
    out = tmp_path / "resumed"
    run_one(str(out), "rge-efr", {"bootstrap": BOOT}, 5, 100, False)
    assert len(RunStore.open(out)) == 100
    run_one(str(out), "rge-efr", {"bootstrap": BOOT}, 5, N, False)  # resumes from the history
    a, b = RunStore.open(reference).records, RunStore.open(out).records
    assert len(a) == len(b) == N
    assert all(x.equals(y) for x, y in zip(a, b, strict=True))


@pytest.mark.parametrize("stall_window", [None, 0])
def test_strategy_state_is_rebuilt_by_update(reference, stall_window):
    """Two strategies fed the same history propose the same, kind for kind. With the default
    stall window the history's end decides whether proposals are all random (a run whose last
    episodes left the ball still: the twin's trajectory, which differs between CPUs); without
    it every kind is proposed whatever the trajectory."""
    recs = RunStore.open(reference).records
    options = {} if stall_window is None else {"stall_window": stall_window}
    s1 = make_strategy("mge-efr", scene=TWIN_ARENA, bootstrap=BOOT, **options)
    s2 = make_strategy("mge-efr", scene=TWIN_ARENA, bootstrap=BOOT, **options)
    for r in recs:
        s1.update(r)
    for r in recs:
        s2.update(r)
    assert s1.still == s2.still
    ctx = Observation(ball=recs[-1].ball[:2])
    for k in range(20):
        p1 = s1.propose(ctx, np.random.default_rng([1, k]))
        p2 = s2.propose(ctx, np.random.default_rng([1, k]))
        assert np.array_equal(p1.theta, p2.theta) and np.array_equal(p1.goal, p2.goal)
        assert p1.kind == p2.kind and p1.module == p2.module
    kinds = {s1.propose(ctx, np.random.default_rng([2, k])).kind for k in range(50)}
    if s1.random_share() < 1:
        assert kinds == {"explore", "exploit", "random"}  # random: the rig's 10% babbling
    else:
        assert kinds == {"random"}  # in a stall (the default window only)
    if stall_window == 0:
        assert s1.random_share() < 1


def test_bad_options_are_one_line_errors():
    with pytest.raises(
        StrategyError,
        match=r"option bootstap is unknown \(did you mean 'bootstrap'\?\); known: bootstrap, ",
    ):
        make_strategy("rge-efr", scene=TWIN_ARENA, bootstap=3)
    with pytest.raises(StrategyError, match="option goals must be one of 'uniform', 'normal'"):
        make_strategy("rge-efr", scene=TWIN_ARENA, goals="gaussian")
    with pytest.raises(StrategyError, match="option sigma must be >= 0"):
        make_strategy("rge-efr", scene=TWIN_ARENA, sigma=-0.1)
    with pytest.raises(StrategyError, match="option exploit must be a probability"):
        make_strategy("mge-efr", scene=TWIN_ARENA, exploit=2)
    with pytest.raises(StrategyError, match="option bootstrap must be an integer"):
        make_strategy("rge-efr", scene=TWIN_ARENA, bootstrap="many")
    with pytest.raises(StrategyError, match="strategy 'rpe': option sigma is unknown"):
        make_strategy(
            "rpe", scene=TWIN_ARENA, sigma=0.1
        )  # rpe has no options: none is stored silently
    with pytest.raises(StrategyError, match="needs option vae"):
        make_strategy("rge-vae", scene=TWIN_ARENA)
