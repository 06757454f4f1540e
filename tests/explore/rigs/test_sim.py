"""The twin rig seen through the ball tracker, as a real rig sees its arena."""

from __future__ import annotations

import numpy as np
import pytest

from explore.rigs.rig import RigConfig, RigError, make_rig
from explore.runs.config import RunConfig
from explore.runs.open_run import open_run
from sim.twin import Twin


def test_tracked_ball_positions_match_the_twin_or_are_reported_unseen(tmp_path):
    config = RunConfig(rig=RigConfig(options={"ball": "tracker"}), seed=5, episodes=25)
    with open_run(tmp_path / "run", config) as run:
        run.explore()
        store = run.store
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
    with pytest.raises(RigError, match="option ball must be one of 'truth', 'tracker', got 'gps'"):
        make_rig(RigConfig(options={"ball": "gps"}))
