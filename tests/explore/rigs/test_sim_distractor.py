"""The twin's distractor: a red ball that walks on the ring between episodes, that neither the
arm nor the ball ever moves, seen by the camera where the state says, reported by the
engineered features as a module of its own, and restored exactly on resume."""

from __future__ import annotations

import math
from itertools import pairwise

import cv2
import numpy as np
import pytest

from explore.learner.goal_spaces import EngineeredGoalSpace, wrap_safe_features
from explore.rigs.arena import R_MAX, R_MIN, TWIN_ARENA
from explore.rigs.rig import RigConfig, RigError, make_rig
from explore.runs.config import RunConfig, StrategyConfig
from explore.runs.open_run import open_run

WALK = {"distractor": "walk"}


def run(path, episodes: int, seed: int = 6, strategy: str = "rpe") -> list:
    config = RunConfig(
        rig=RigConfig(options=WALK), strategy=StrategyConfig(strategy), seed=seed,
        episodes=episodes,
    )  # fmt: skip
    with open_run(path, config, episodes=episodes) as opened:
        opened.explore()
        return opened.store.records


def test_it_moves_between_episodes_only_and_stays_on_the_ring(tmp_path):
    records = run(tmp_path / "r", 24)
    assert sum(r.ball_moved for r in records) >= 1  # the arm did push the ball meanwhile
    for r in records:
        # during an episode (the arm sweeping the ring) nothing moves it
        np.testing.assert_array_equal(r.context_distractor, r.distractor)
        assert R_MIN - 1e-9 <= math.hypot(*r.distractor) <= R_MAX + 1e-9
    steps = [np.linalg.norm(b.context_distractor - a.distractor) for a, b in pairwise(records)]
    assert min(steps) > 0  # a step before every episode
    angles = np.unwrap([math.atan2(r.distractor[1], r.distractor[0]) for r in records])
    assert np.ptp(angles) > 0.5  # it wanders


def test_the_camera_sees_it_where_the_state_says(tmp_path):
    """The red disc's centroid in the outcome image against the distractor's projection."""
    from sim.camera import SimCamera

    records = run(tmp_path / "r", 6)
    rig = make_rig(RigConfig(options=WALK))
    camera = SimCamera(rig.sensor.twin, size=(64, 64))
    for r in records:
        hsv = cv2.cvtColor(r.image, cv2.COLOR_BGR2HSV)
        red = ((hsv[..., 0] < 8) | (hsv[..., 0] > 172)) & (hsv[..., 1] > 120)
        ys, xs = np.nonzero(red)
        assert len(xs) > 5
        projected = camera.project(np.array([[*r.distractor, rig.sensor.twin.ball_radius]]))[0]
        assert np.hypot(xs.mean() - projected[0], ys.mean() - projected[1]) < 1.0


def test_the_engineered_features_report_both_balls_as_modules():
    space = EngineeredGoalSpace(distractor=True, hand_module=True, scene=TWIN_ARENA)
    assert [len(m) for m in space.modules] == [3, 3, 2] and space.context_dim == 6

    class Rec:
        ball, distractor = np.array([0.15, 0.0]), np.array([0.0, -0.14])
        context_ball, context_distractor = np.array([0.14, 0.02]), np.array([0.01, -0.15])
        end_effector = np.array([[0.1, 0.1, 0.05]])

    ring = (R_MIN, R_MAX)
    o = space.outcome(Rec)
    np.testing.assert_allclose(o[:3], wrap_safe_features(Rec.ball, ring))
    np.testing.assert_allclose(o[3:6], wrap_safe_features(Rec.distractor, ring))
    np.testing.assert_allclose(
        space.context(Rec),
        np.concatenate(
            [
                wrap_safe_features(Rec.context_ball, ring),
                wrap_safe_features(Rec.context_distractor, ring),
            ]
        ),
    )
    Rec.distractor = np.full(2, np.nan)  # not seen: its module skips the record
    assert space.module_outcomes(space.outcome(Rec))[1] is None
    # without a distractor the space is the ball's alone, as before
    assert [len(m) for m in EngineeredGoalSpace(scene=TWIN_ARENA).modules] == [3]


def test_a_resumed_run_walks_it_exactly_as_the_uninterrupted_run(tmp_path):
    whole = run(tmp_path / "a", 10, strategy="mge-efr")
    run(tmp_path / "b", 5, strategy="mge-efr")
    resumed = run(tmp_path / "b", 10, strategy="mge-efr")
    assert all(x.equals(y) for x, y in zip(whole, resumed, strict=True))


def test_bad_distractor_options_are_one_line_errors():
    with pytest.raises(RigError, match="option distractor must be one of 'none', 'walk'"):
        make_rig(RigConfig(options={"distractor": "sideways"}))
    with pytest.raises(RigError, match=r"option distractor_step must be radians in \[0, pi\]"):
        make_rig(RigConfig(options={"distractor": "walk", "distractor_step": 7}))
