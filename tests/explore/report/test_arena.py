"""The arena figure of a run report: goals placed in the arena, the ring's sectors reached,
the goal-to-outcome distance; and ``ergo report`` writes it with its table rows."""

from __future__ import annotations

import dataclasses
import struct
from pathlib import Path

import numpy as np

from explore.cli import main
from explore.learner.goal_spaces import ring_polar_features, wrap_safe_features
from explore.report.arena import (
    N_SECTORS,
    arena_figure,
    confinement,
    features_to_xy,
    goal_positions,
    sector_of,
)
from explore.report.figures import FIG_PX
from explore.report.run_data import load_run
from explore.rigs.arena import TWIN_ARENA


def png_size(path: Path) -> tuple[int, int]:
    head = path.read_bytes()[:24]
    return struct.unpack(">II", head[16:24])


def test_features_are_inverted_exactly():
    rng = np.random.default_rng(0)
    r = rng.uniform(*TWIN_ARENA.ring, 50)
    t = rng.uniform(-np.pi, np.pi, 50)
    xy = np.c_[r * np.cos(t), r * np.sin(t)]
    ring = TWIN_ARENA.ring
    np.testing.assert_allclose(features_to_xy(wrap_safe_features(xy, ring), "wrap-safe",
                                              TWIN_ARENA), xy, atol=1e-12)  # fmt: skip
    np.testing.assert_allclose(features_to_xy(ring_polar_features(xy, ring), "polar",
                                              TWIN_ARENA), xy, atol=1e-12)  # fmt: skip
    h = TWIN_ARENA.ball_half_width
    np.testing.assert_allclose(features_to_xy(xy / h, "cartesian", TWIN_ARENA), xy)
    assert sector_of(np.array([[1.0, 0.01], [0.0, 1.0], [-1.0, -0.01]])).tolist() == [0, 3, 6]


def test_confinement_counts_sectors_and_goals(goal_run):
    run = load_run(goal_run)
    # a made-up confinement: every ball in sector 1, every goal aimed at sector 7
    a_ball, a_goal = np.radians(45.0), np.radians(225.0)
    r = np.mean(TWIN_ARENA.ring)
    ball = np.tile([r * np.cos(a_ball), r * np.sin(a_ball)], (run.n, 1))
    goal_xy = np.array([r * np.cos(a_goal), r * np.sin(a_goal)])
    has_goal = np.all(np.isfinite(run.goals), axis=1)
    goals = np.where(has_goal[:, None], wrap_safe_features(goal_xy, TWIN_ARENA.ring), np.nan)
    moved = np.ones(run.n, dtype=bool)
    fake = dataclasses.replace(run, ball=ball, goals=goals, ball_moved=moved)
    c = confinement(fake)
    assert c.sectors_reached == 1 and c.ball_sectors[1] == run.n
    assert c.goal_sectors[7] == has_goal.sum() == 4 and c.goal_sectors.sum() == 4
    np.testing.assert_allclose(c.goal_distance, 2 * r)  # across the ring
    assert len(c.ball_sectors) == N_SECTORS


def test_learned_goals_are_placed_by_an_affine_map(goal_run):
    # a learned space stands in: the run's goals and outcomes through an affine code
    run = load_run(goal_run)
    a = np.array([[2.0, 0.5, -1.0], [0.3, -1.5, 0.7]])
    ball = np.random.default_rng(1).uniform(-0.15, 0.15, (run.n, 2))
    code = ball @ a + 0.1
    has_goal = np.ones(run.n, dtype=bool)  # every episode a goal episode of module 0
    goal_xy = ball[::-1] * 0.9  # some other positions
    fake = dataclasses.replace(
        run,
        ball=ball,
        module=np.zeros(run.n, dtype=int),
        meta={**run.meta, "config": {**run.config, "strategy": {"name": "rge-sae"}}},
        goals=np.where(has_goal[:, None], goal_xy @ a + 0.1, np.nan),
        reached=np.where(has_goal[:, None], code, np.nan),
    )
    placed, how = goal_positions(fake)
    assert "affine map, R² 1.00" in how
    np.testing.assert_allclose(placed[has_goal], goal_xy[has_goal], atol=1e-9)
    # a module that does not locate the ball is left out
    same = np.ones_like(code)  # the same code wherever the ball is
    blind = dataclasses.replace(fake, reached=np.where(has_goal[:, None], same, np.nan))
    placed, how = goal_positions(blind)
    assert how == "no module locates the ball" and not np.isfinite(placed).any()
    assert arena_figure(blind, Path("unused.png")) is None


def test_report_writes_the_arena_figure_and_its_rows(goal_run, tmp_path):
    out = tmp_path / "report"
    assert main(["report", str(goal_run), "--out", str(out)]) == 0
    assert png_size(out / "arena.png") == FIG_PX
    md = (out / "summary.md").read_text()
    assert "| ring sectors a moved ball entered |" in md
    assert "| goal to outcome in the arena, median |" in md and "(wrap-safe features)" in md
    assert "![arena](arena.png)" in md
