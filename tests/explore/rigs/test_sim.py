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


def test_the_twin_s_watchdog_lets_a_passing_wedge_through_and_stops_a_stuck_arm():
    """Pressing the tool into the floor holds joints at full load. For 3 s (the longest a
    wedge against the twin's guard was measured to last, 2.5 s, is under it) the run goes on;
    held there past the twin's 5 s, the watchdog stops it, torque off."""
    import numpy as np
    import pytest

    from explore.rigs.rig import RigConfig, make_rig
    from explore.rigs.sim import TWIN_WATCHDOG_HOLD_S
    from robot.errors import SafetyStop

    into_floor = np.array([0.0, 1.9, 1.4, 0.0, 1.2, 0.0])  # m2..m5 bent down past the floor
    with make_rig(RigConfig()) as rig:
        assert rig.arm.watchdog.hold_s == TWIN_WATCHDOG_HOLD_S == 5.0
        for q in np.linspace(rig.arm.spec.rest, into_floor, 40):
            rig.arm.command(q)
            rig.clock.advance(0.025)
        loads = []
        for _ in range(30):  # 3 s at full load: reads every 0.1 s, as the settle does
            rig.clock.advance(0.1)
            loads.append(np.abs(rig.arm.read().loads).max())
        assert min(loads) > 0.9  # it was pressing all along
        with pytest.raises(SafetyStop, match="load"):
            for _ in range(40):
                rig.clock.advance(0.1)
                rig.arm.read()
        assert not rig.sensor.twin.torque_enabled()


def test_the_tracker_says_why_the_ball_is_unseen_once_per_spell(caplog):
    """A run's log says why its ball positions are unknown: one INFO line when the tracker
    stops seeing the ball (or its reason changes), none while the reason stays the same, even
    when its figures change from frame to frame."""
    import logging

    from explore.rigs.ball import tracker_locator
    from explore.rigs.sim import twin_arena_model
    from sim.camera import SimCamera
    from vision.tracker import BallTracker

    twin = Twin()
    with SimCamera(twin) as camera:
        locate = tracker_locator(twin_arena_model(camera))
        seen = camera.read().image
    blank = np.zeros_like(seen)  # nothing ball-coloured: the ball gone from view
    u = BallTracker().track(seen).pixel[0]
    halves = []  # the ball's left part hidden, two amounts: "not round", other figures
    for cut in (0.0, 2.0):
        half = seen.copy()
        half[:, : int(u - cut)] = 0
        halves.append(half)
    with caplog.at_level(logging.INFO, logger="explore.rigs.ball"):
        assert np.all(np.isfinite(locate(seen)))
        assert np.all(np.isnan(locate(blank))) and np.all(np.isnan(locate(blank)))
        assert np.all(np.isfinite(locate(seen)))
        assert np.all(np.isnan(locate(blank)))
        assert np.all(np.isnan(locate(halves[0]))) and np.all(np.isnan(locate(halves[1])))
    lines = [r.getMessage() for r in caplog.records if r.name == "explore.rigs.ball"]
    assert lines[:2] == ["ball not seen: no ball-coloured blob"] * 2
    assert len(lines) == 3 and lines[2].startswith("ball not seen: ball-coloured blob not round")
    first, second = (BallTracker().track(h).reason for h in halves)
    assert first != second  # the figures changed, the line was not repeated
