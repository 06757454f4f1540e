"""The ``sim`` rig: the MuJoCo twin in-process (SimArm + SimCamera + TwinClock)."""

from __future__ import annotations

import math

import numpy as np

from explore.ball import tracker_locator, twin_arena_model
from explore.clock import TwinClock
from explore.rig import Rig, RigConfig, RigError
from sim import RENDER_QUALITIES
from sim.arm import SimArm
from sim.camera import SimCamera
from sim.twin import SCENE, SCENE_DISTRACTOR, Twin


def make_sim_rig(config: RigConfig) -> Rig:
    """Options: ``render_size`` [h, w] of the overhead frame (default 240 x 240; with the ground
    truth the outcome image is rendered at its own size and no frame is taken); ``ball``:
    ``truth`` (default: the twin's ground truth) or ``tracker`` (the ball tracker on the
    overhead frames, as on a real rig, with the camera's exact arena model); ``ball_reset``:
    ``none`` (default: the ball stays where the last episode left it, as on the real rig) or
    ``start`` (put back at its start position before every episode, as in the paper's
    simulated ArmBall, where the context never changes); ``render_quality``: ``chosen``
    (default: the scene's own settings, docs/twin.md) or ``legacy`` (MuJoCo's default quality
    and full frames reduced to the observation, the twin's images before 2026-12-01);
    ``distractor``: ``none`` (default) or ``walk``: a second ball (red) that the arm cannot
    move, taking a random step on the ball's ring before every episode (``distractor_walk``,
    ``distractor_step`` its angle's standard deviation, rad; default 0.5)."""
    size = tuple(config.options.get("render_size", (240, 240)))
    ball = config.options.get("ball", "truth")
    if ball not in ("truth", "tracker"):
        raise RigError(f"rig option ball={ball!r}: expected 'truth' or 'tracker'")
    reset = config.options.get("ball_reset", "none")
    if reset not in ("none", "start"):
        raise RigError(f"rig option ball_reset={reset!r}: expected 'none' or 'start'")
    quality = config.options.get("render_quality", "chosen")
    if quality not in RENDER_QUALITIES:
        raise RigError(
            f"rig option render_quality={quality!r}: expected one of {', '.join(RENDER_QUALITIES)}"
        )
    distractor = config.options.get("distractor", "none")
    if distractor not in DISTRACTORS:
        raise RigError(
            f"rig option distractor={distractor!r}: expected one of {', '.join(DISTRACTORS)}"
        )
    step = config.options.get("distractor_step", DISTRACTOR_STEP)
    if not isinstance(step, int | float) or isinstance(step, bool) or not 0 <= step <= math.pi:
        raise RigError(f"rig option distractor_step={step!r}: expected radians in [0, pi]")
    scene = SCENE_DISTRACTOR if distractor == "walk" else SCENE
    twin = Twin(scene, render_size=size, render_quality=quality)  # type: ignore[arg-type]
    camera = SimCamera(twin)
    locator = tracker_locator(twin_arena_model(camera)) if ball == "tracker" else None

    def before_episode(rng: np.random.Generator) -> None:
        if reset == "start":
            twin.place_ball()
        if distractor == "walk":
            twin.place_distractor(distractor_walk(twin.distractor_position()[:2], step, rng))

    return Rig(
        arm=SimArm(twin), camera=camera, clock=TwinClock(twin), config=config, twin=twin,
        ball_locator=locator,
        before_episode=before_episode if reset == "start" or distractor == "walk" else None,
        # with the ground truth, the outcome image is all a frame is for: render it at its size
        square_view=(
            (lambda side: camera.read_square(side).image)
            if locator is None and quality == "chosen"
            else None  # legacy: reduced from the full frame, as those images were made
        ),
    )  # fmt: skip


DISTRACTORS = ("none", "walk")
# The distractor's walk before each episode, on the ring where the ball's centre lies
# (explore/goal_spaces.py R_MIN..R_MAX): its angle takes a N(0, step) step, 0.5 rad by default
# (75 mm at the ring's middle, about 6 of the metric's cells), its radius a N(0, 1 cm) step
# reflected into the ring. Guesses: it wanders all round within some 100 episodes, and one
# episode's move is a fraction of the ring, as ArmBalls' distractor moves a fraction of its
# square per episode (docs/armballs.md).
DISTRACTOR_STEP = 0.5  # rad
DISTRACTOR_RADIUS_STEP = 0.01  # m


def distractor_walk(xy: np.ndarray, step: float, rng: np.random.Generator) -> np.ndarray:
    """One step of the distractor's random walk from ``xy`` (2,) m: the new (x, y), m."""
    from explore.goal_spaces import R_MAX, R_MIN

    r = float(np.hypot(*xy)) + rng.normal(0.0, DISTRACTOR_RADIUS_STEP)
    span = R_MAX - R_MIN
    r = R_MIN + span - abs(span - abs(r - R_MIN) % (2 * span))  # reflected into the ring
    t = float(np.arctan2(xy[1], xy[0])) + rng.normal(0.0, step)
    return np.array([r * np.cos(t), r * np.sin(t)])
