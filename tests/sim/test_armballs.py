"""ArmBalls / Arm-2-Balls: kinematics, the catch rule, the distractor, the image, determinism,
the motor primitive, and RPE against the published campaign (docs/armballs.md)."""

from __future__ import annotations

import csv
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from explore.runs.metrics import CellCounter
from sim.armballs import (
    ARM_2_BALLS,
    ARM_BALLS,
    NOT_CAUGHT,
    ArmBallsConfig,
    ArmBallsEnv,
    PrimitiveParameterError,
    RbfPrimitive,
    initial_state,
    play_commands,
    render_scene,
    step,
)
from sim.armballs.kinematics import hand_position, link_points

LINKS = np.array(ARM_2_BALLS.link_lengths)
PUBLISHED = Path(__file__).resolve().parents[2] / "docs" / "armballs_published.csv"


def pose(*first: float) -> np.ndarray:
    """Joint commands (7,) starting with ``first``, the rest 0."""
    c = np.zeros(7)
    c[: len(first)] = first
    return c


# ---- kinematics ----------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("commands", "hand"),
    [
        (pose(), (1.0, 0.0)),  # straight along +x
        (pose(1.0), (-1.0, 0.0)),  # the whole arm turned by pi
        (pose(0.5), (0.0, 1.0)),  # turned by pi/2
        (pose(-0.5), (0.0, -1.0)),
        (pose(0.5, -0.5), (0.7, 0.3)),  # first link up (0.3), the rest back along +x (0.7)
        (pose(-0.5, 0.5, 0.5), (0.2, 0.2)),  # down 0.3, along x 0.2, up 0.5
        (pose(0, 0, 0, 0, 0, 0, 1.0), (0.9, 0.0)),  # last link folded back: 0.95 - 0.05
    ],
)
def test_hand_position_of_hand_made_poses(commands: np.ndarray, hand: tuple[float, float]):
    np.testing.assert_allclose(hand_position(commands, LINKS), hand, atol=1e-12)


@pytest.mark.parametrize(
    ("joint", "cap"), [(1, 0.6), (2, 0.6), (3, 0.8), (4, 0.8), (5, 0.9), (6, 0.9)]
)
def test_a_joint_at_pi_caps_the_hands_distance(joint: int, cap: float):
    # what confines the stalled MGE-EFR runs (docs/results_armballs.md, "Runs confined by a
    # folded arm"): a joint at pi folds its link back, capping the hand's distance from the
    # base (links 0.3, 0.2, 0.2, 0.1, 0.1, 0.05, 0.05); the cap is reached with the next
    # joint at pi too (the rest of the arm straight out again)
    rng = np.random.default_rng(joint)
    poses = rng.uniform(-1.0, 1.0, (20000, 7))
    poses[:, joint] = rng.choice([-1.0, 1.0], len(poses))
    assert np.linalg.norm(hand_position(poses, LINKS), axis=1).max() <= cap + 1e-12
    best = pose(*([0.0] * joint), 1.0, *([1.0] if joint < 6 else []))
    assert np.linalg.norm(hand_position(best, LINKS)) == pytest.approx(cap)


def test_the_first_joint_at_pi_keeps_the_hand_left_of_x_04():
    # joint 0 at pi puts the first link's end at (-0.3, 0): the other 0.7 reach x <= 0.4
    rng = np.random.default_rng(0)
    poses = rng.uniform(-1.0, 1.0, (20000, 7))
    poses[:, 0] = rng.choice([-1.0, 1.0], len(poses))
    assert hand_position(poses, LINKS)[:, 0].max() <= 0.4 + 1e-12
    np.testing.assert_allclose(hand_position(pose(1.0, 1.0), LINKS), (0.4, 0.0), atol=1e-12)


def test_link_points_end_at_the_hand_and_batch_like_single_poses():
    rng = np.random.default_rng(0)
    commands = rng.uniform(-1, 1, (4, 5, 7))
    pts = link_points(commands, LINKS)
    assert pts.shape == (4, 5, 7, 2)
    np.testing.assert_allclose(pts[..., -1, :], hand_position(commands, LINKS), atol=1e-12)
    np.testing.assert_allclose(pts[2, 3], link_points(commands[2, 3], LINKS), atol=1e-12)
    # consecutive points are one link apart
    seg = np.diff(np.concatenate([np.zeros((4, 5, 1, 2)), pts], axis=-2), axis=-2)
    np.testing.assert_allclose(np.linalg.norm(seg, axis=-1), np.broadcast_to(LINKS, (4, 5, 7)))


# ---- the catch rule ------------------------------------------------------------------------


def scene_with_ball_at(ball: tuple[float, float], **kw) -> ArmBallsConfig:
    return replace(ARM_BALLS, ball_start=ball, **kw)


def test_ball_is_caught_when_the_hand_comes_within_the_catch_radius():
    # pose(0.5, -0.5) puts the hand at (0.7, 0.3); the catch radius is 0.1
    near = scene_with_ball_at((0.7, 0.3 + 0.0999))
    far = scene_with_ball_at((0.7, 0.3 + 0.1001))
    cmds = np.stack([pose(), pose(0.5, -0.5), pose()])[None]  # reach over the ball, then back
    held = play_commands(cmds, None, near)
    assert held.catch_step[0] == 1
    # from the catch on, the ball is at the hand: back at (1, 0) after the last step
    np.testing.assert_allclose(held.ball[0, 0], near.ball_start)
    np.testing.assert_allclose(held.ball[0, 1:], held.hand[0, 1:])
    np.testing.assert_allclose(held.ball[0, -1], (1.0, 0.0), atol=1e-12)
    missed = play_commands(cmds, None, far)
    assert missed.catch_step[0] == NOT_CAUGHT
    np.testing.assert_allclose(missed.ball[0], np.broadcast_to(far.ball_start, (3, 2)))


def test_a_caught_ball_follows_the_hand_even_far_from_where_it_was_caught():
    cfg = scene_with_ball_at((0.0, 1.0))  # under the hand of pose(0.5)
    cmds = np.stack([pose(0.5), pose(1.0), pose(-0.5), pose(0.25)])[None]
    paths = play_commands(cmds, None, cfg)
    assert paths.catch_step[0] == 0
    np.testing.assert_allclose(paths.ball[0], hand_position(cmds[0], LINKS), atol=1e-12)


def test_the_vectorised_episode_matches_the_step_by_step_rules():
    env = ArmBallsEnv(ARM_2_BALLS)
    rng = np.random.default_rng(3)
    commands = env.primitive.commands(rng.uniform(-1, 1, (3000, env.n_params)))
    noise = rng.standard_normal((3000, ARM_2_BALLS.n_steps, 2))
    paths = play_commands(commands, noise, ARM_2_BALLS)
    caught = np.flatnonzero(paths.catch_step != NOT_CAUGHT)
    assert len(caught) >= 20  # about 2% of random episodes catch the ball
    for i in [*caught[:20], *np.flatnonzero(paths.catch_step == NOT_CAUGHT)[:5]]:
        state = initial_state(ARM_2_BALLS)
        for t in range(ARM_2_BALLS.n_steps):
            state = step(state, commands[i, t], noise[i, t], ARM_2_BALLS)
            np.testing.assert_allclose(state.hand, paths.hand[i, t], atol=1e-12)
            np.testing.assert_allclose(state.ball, paths.ball[i, t], atol=1e-12)
            np.testing.assert_allclose(state.distractor, paths.distractor[i, t], atol=1e-12)
            assert state.caught == (paths.catch_step[i] != NOT_CAUGHT and t >= paths.catch_step[i])


def test_every_episode_starts_from_the_same_scene():
    env = ArmBallsEnv(ARM_2_BALLS)
    rng = np.random.default_rng(0)
    paths = env.play_batch(rng.uniform(-1, 1, (2000, env.n_params)), rng)
    not_caught = paths.catch_step == NOT_CAUGHT
    np.testing.assert_array_equal(
        paths.ball[not_caught, -1], np.broadcast_to((0.6, 0.6), (not_caught.sum(), 2))
    )
    first = paths.distractor[:, 0] - np.asarray(ARM_2_BALLS.distractor_start)
    assert np.all(np.abs(first) < 6 * ARM_2_BALLS.distractor_noise)  # one step from its start
    s = initial_state(ARM_2_BALLS)
    np.testing.assert_allclose(s.hand, (1.0, 0.0))
    assert not s.caught


# ---- the distractor ------------------------------------------------------------------------


def test_the_distractor_never_moves_the_ball():
    rng = np.random.default_rng(5)
    params = rng.uniform(-1, 1, (3000, ARM_2_BALLS.n_params))
    alone = ArmBallsEnv(ARM_BALLS).play_batch(params, np.random.default_rng(0))
    with_a = ArmBallsEnv(ARM_2_BALLS).play_batch(params, np.random.default_rng(1))
    with_b = ArmBallsEnv(ARM_2_BALLS).play_batch(params, np.random.default_rng(2))
    assert np.any(alone.catch_step != NOT_CAUGHT)
    for other in (with_a, with_b):
        np.testing.assert_array_equal(other.ball, alone.ball)
        np.testing.assert_array_equal(other.catch_step, alone.catch_step)
    assert not np.allclose(with_a.distractor, with_b.distractor)


def test_the_arm_never_moves_the_distractor():
    # the distractor sits on the hand's path and does not walk: it must stay where it is
    cfg = replace(ARM_2_BALLS, distractor_start=(0.7, 0.3), distractor_noise=0.0)
    cmds = np.stack([pose(0.5, -0.5), pose(0.5, -0.5), pose(0.4)])[None]
    paths = play_commands(cmds, np.ones((1, 3, 2)), cfg)
    np.testing.assert_allclose(paths.hand[0, 0], (0.7, 0.3), atol=1e-12)
    np.testing.assert_array_equal(paths.distractor[0], np.broadcast_to((0.7, 0.3), (3, 2)))


def test_the_distractor_walks_with_the_published_noise_and_stays_in_its_square():
    rng = np.random.default_rng(11)
    env = ArmBallsEnv(ARM_2_BALLS)
    paths = env.play_batch(rng.uniform(-1, 1, (2000, env.n_params)), rng)
    d = paths.distractor
    assert np.all(np.abs(d) <= ARM_2_BALLS.distractor_limit)
    assert np.any(np.abs(d) == ARM_2_BALLS.distractor_limit)  # it does reach the bound
    steps = np.diff(d, axis=1)
    free = np.all(np.abs(d[:, 1:]) < ARM_2_BALLS.distractor_limit, axis=-1)
    free &= np.all(np.abs(d[:, :-1]) < ARM_2_BALLS.distractor_limit, axis=-1)
    sd = steps[free].std()
    assert abs(sd - ARM_2_BALLS.distractor_noise) < 0.005, sd


# ---- the image -----------------------------------------------------------------------------


def decode_centre(image: np.ndarray, rgb: tuple[int, int, int]) -> tuple[np.ndarray, int]:
    """Centre of the pixels of one colour, in world units, by the stated convention: the
    64-pixel image spans [-1, 1] on both axes, pixel i covering [i, i + 1), x to the right
    and y downwards. Returns the centre and the pixel count."""
    want = np.asarray(rgb) > 127
    mask = np.all((image > 127) == want, axis=-1)
    rows, cols = np.nonzero(mask)
    size = image.shape[0]
    centre = np.array([cols.mean() + 0.5, rows.mean() + 0.5]) / (size / 2.0) - 1.0
    return centre, int(mask.sum())


def test_the_image_shows_the_balls_where_the_state_says():
    rng = np.random.default_rng(2)
    cfg = ARM_2_BALLS
    seen = 0
    while seen < 30:
        ball, distractor = rng.uniform(-0.8, 0.8, (2, 2))
        if (
            np.linalg.norm(ball - distractor)
            < cfg.ball_draw_radius + cfg.distractor_draw_radius + 0.1
        ):
            continue
        seen += 1
        img = render_scene(ball, distractor, config=cfg)
        assert img.shape == (64, 64, 3) and img.dtype == np.uint8
        got_ball, n_ball = decode_centre(img, (255, 255, 0))
        got_distractor, n_distractor = decode_centre(img, (0, 0, 255))
        np.testing.assert_allclose(got_ball, ball, atol=0.5 / 32)  # half a pixel
        np.testing.assert_allclose(got_distractor, distractor, atol=0.5 / 32)
        # disc areas: radius 0.17 and 0.15 world units at 32 pixels per unit
        assert abs(n_ball - np.pi * (0.17 * 32) ** 2) < 0.15 * np.pi * (0.17 * 32) ** 2
        assert abs(n_distractor - np.pi * (0.15 * 32) ** 2) < 0.15 * np.pi * (0.15 * 32) ** 2


def test_an_episode_image_is_its_final_scene():
    env = ArmBallsEnv(ARM_2_BALLS)
    rng = np.random.default_rng(4)
    out = None
    while out is None or not out.caught:  # a caught ball, so that it has moved
        out = env.play(rng.uniform(-1, 1, env.n_params), rng)
    if np.linalg.norm(out.ball - out.distractor) > 0.45:
        np.testing.assert_allclose(
            decode_centre(out.image, (255, 255, 0))[0], out.ball, atol=0.5 / 32
        )
    np.testing.assert_array_equal(
        out.image, render_scene(out.ball, out.distractor, config=env.config)
    )
    np.testing.assert_allclose(out.ball, out.hand)


def test_armballs_images_have_no_distractor_and_the_distractor_is_drawn_over_the_ball():
    img = render_scene(np.array([0.2, -0.3]), None, config=ARM_BALLS)
    assert not np.any(img[..., 2] > 127)  # no blue
    both = render_scene(np.array([0.2, -0.3]), np.array([0.2, -0.3]), config=ARM_2_BALLS)
    centre = np.round((np.array([0.2, -0.3]) + 1.0) * 32).astype(int)  # (col, row)
    np.testing.assert_array_equal(both[centre[1], centre[0]], (0, 0, 255))


def test_the_arm_can_be_drawn_for_viewing_but_is_not_observed():
    env = ArmBallsEnv(ARM_BALLS)
    out = env.play(np.zeros(env.n_params), np.random.default_rng(0))
    assert not np.any(np.all(out.image == (0, 255, 0), axis=-1))
    drawn = render_scene(out.ball, None, arm_commands=pose(), config=ARM_BALLS)
    row = 31  # the arm lies along +x from the centre, on the row just above y = 0
    assert np.all(drawn[row : row + 2, 34:62, 1].max(axis=0) > 127)


# ---- determinism ---------------------------------------------------------------------------


def test_same_seed_same_episodes_and_images():
    env = ArmBallsEnv(ARM_2_BALLS)
    runs = []
    for _ in range(2):
        rng = np.random.default_rng(42)
        runs.append([env.play(rng.uniform(-1, 1, env.n_params), rng) for _ in range(30)])
    for a, b in zip(*runs, strict=True):
        np.testing.assert_array_equal(a.ball, b.ball)
        np.testing.assert_array_equal(a.distractor, b.distractor)
        np.testing.assert_array_equal(a.image, b.image)
    rng = np.random.default_rng(43)
    other = env.play(np.zeros(env.n_params), rng)
    assert not np.array_equal(other.distractor, runs[0][0].distractor)


def test_a_batch_draws_what_single_episodes_draw_in_turn():
    env = ArmBallsEnv(ARM_2_BALLS)
    params = np.random.default_rng(9).uniform(-1, 1, (25, env.n_params))
    batch = env.play_batch(params, np.random.default_rng(7))
    rng = np.random.default_rng(7)
    for i, p in enumerate(params):
        one = env.play(p, rng, render=False)
        np.testing.assert_allclose(one.distractor, batch.distractor[i, -1], atol=1e-12)
        np.testing.assert_array_equal(one.ball, batch.ball[i, -1])
        assert one.catch_step == batch.catch_step[i]
        assert one.image is None


# ---- the motor primitive -------------------------------------------------------------------


def test_rbf_basis_is_the_filtered_impulses_of_the_original():
    # the original's construction: unit impulses at the centres of a 1.25 T-long array,
    # Gaussian-filtered (sdev 10 steps, scipy's default truncation), divided by the maximum
    from scipy.ndimage import gaussian_filter1d

    prim = RbfPrimitive(ARM_2_BALLS)
    t, k = ARM_2_BALLS.n_steps, ARM_2_BALLS.n_rbf
    impulses = np.zeros((int(t * 1.25), k))
    impulses[[8, 15, 22, 29, 36, 43, 50], np.arange(k)] = 1.0
    filtered = gaussian_filter1d(impulses, ARM_2_BALLS.rbf_sdev, axis=0, mode="constant")
    np.testing.assert_allclose(prim.basis, (filtered / filtered.max())[:t], atol=1e-12)


def test_commands_are_the_weighted_bumps_clipped_to_the_unit_range():
    prim = RbfPrimitive(ARM_2_BALLS)
    rng = np.random.default_rng(1)
    p = rng.uniform(-0.1, 0.1, ARM_2_BALLS.n_params)  # small: no clipping
    c = prim.commands(p)
    assert c.shape == (50, 7)
    np.testing.assert_allclose(c[:, 3], prim.basis @ p[3 * 7 : 4 * 7], atol=1e-12)  # joint-major
    full = prim.commands(np.ones(ARM_2_BALLS.n_params))
    assert full.max() == 1.0 and np.all(full >= -1.0)
    assert prim.commands(np.stack([p, -p])).shape == (2, 50, 7)


@pytest.mark.parametrize(
    ("params", "message"),
    [
        (np.zeros(48), "shape"),
        (np.zeros((2, 3, 49)), "shape"),
        (np.full(49, np.nan), "NaN"),
        (np.full(49, 1.5), r"\[-1, 1\]"),
    ],
)
def test_bad_parameters_are_refused_with_a_clear_error(params: np.ndarray, message: str):
    with pytest.raises(PrimitiveParameterError, match=message):
        ArmBallsEnv().play(params, np.random.default_rng(0))


def test_single_and_batch_episodes_refuse_the_other_shape():
    env = ArmBallsEnv()
    with pytest.raises(PrimitiveParameterError, match="one episode"):
        env.play(np.zeros((1, 49)), np.random.default_rng(0))
    with pytest.raises(PrimitiveParameterError, match="a batch"):
        env.play_batch(np.zeros(98), np.random.default_rng(0))


def test_bad_settings_are_refused():
    with pytest.raises(ValueError, match="sum to 1"):
        ArmBallsConfig(link_lengths=(0.5, 0.4))
    with pytest.raises(ValueError, match="catch_radius"):
        ArmBallsConfig(catch_radius=0.0)


# ---- RPE against the published campaign ----------------------------------------------------


def test_rpe_is_within_two_published_sd_of_the_published_rpe():
    # RPE is a function of the environment and the motor primitive alone; 8 runs here, the
    # published table has 40 (docs/armballs_published.csv). experiments/armballs_rpe.py: more runs.
    with open(PUBLISHED, newline="") as f:
        pub = {int(r["iterations"]): r for r in csv.DictReader(f) if r["algorithm"] == "RPE"}
    checkpoints = (1000, 3000, 5000, 9666)
    env = ArmBallsEnv(ARM_2_BALLS)
    ratios = []
    for seed in range(8):
        rng = np.random.default_rng(seed)
        balls = env.play_batch(rng.uniform(-1, 1, (9666, env.n_params)), rng).ball[:, -1]
        ratios.append([CellCounter(1.0, 30).add(balls[:n]) / 900 for n in checkpoints])
    mean = np.mean(ratios, axis=0)
    for n, m in zip(checkpoints, mean, strict=True):
        pm, ps = float(pub[n]["mean"]), float(pub[n]["sd"])
        assert abs(m - pm) <= 2 * ps, (n, m, pm, ps)
