"""The twin rig seen through the ball tracker, as a real rig sees its arena."""

from __future__ import annotations

import numpy as np
import pytest

from explore.learner.strategies import make_strategy
from explore.rigs.rig import RigConfig, RigError, make_rig
from explore.runs.explorer import Explorer
from explore.runs.store import RunStore
from sim.twin import Twin


def test_tracked_ball_positions_match_the_twin_or_are_reported_unseen(tmp_path):
    rig = make_rig(RigConfig(options={"ball": "tracker"}))
    store = RunStore.create(tmp_path / "run", {})
    Explorer(rig, make_strategy("rpe"), store, seed=5).run(25)
    twin = Twin()
    seen = 0
    for rec in store:
        twin.set_state(rec.sim_state)
        if np.all(np.isfinite(rec.ball)):
            seen += 1
            assert np.linalg.norm(rec.ball - twin.ball_position()[:2]) < 0.005
        else:
            assert np.all(np.isnan(rec.ball))  # never half a position
    assert seen >= 10  # the arm hides the ball sometimes, not mostly


def test_an_unknown_ball_source_is_refused():
    with pytest.raises(RigError, match="ball='gps'"):
        make_rig(RigConfig(options={"ball": "gps"}))
