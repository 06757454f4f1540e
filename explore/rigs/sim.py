"""The ``sim`` rig: the MuJoCo twin in-process (SimArm + SimCamera + TwinClock)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Literal

import numpy as np

from explore.learner.scene import TWIN_ARENA, Scene
from explore.options import BadOption
from explore.rigs.ball import tracker_locator, twin_arena_model
from explore.rigs.clock import TwinClock
from explore.rigs.rig import Rig, RigConfig, RigError
from explore.rigs.video import VideoOptions
from robot.watchdog import Watchdog
from sim import RENDER_QUALITIES
from sim.arm import SimArm
from sim.camera import SimCamera
from sim.twin import SCENE, SCENE_DISTRACTOR, Twin

# Rendered frame side, pixels: below 16 the tracker has nothing to see, above 2048 a software
# render takes seconds (guesses, on the safe side).
RENDER_SIDE = (16, 2048)
RENDER_SIZE = f"[height, width], integers in [{RENDER_SIDE[0]}, {RENDER_SIDE[1]}]"
# The distractor's walk before each episode, on the ring where the ball's centre lies
# (explore/learner/goal_spaces.py R_MIN..R_MAX): its angle takes a N(0, step) step, 0.5 rad by
# default (75 mm at the ring's middle, about 6 of the metric's cells), its radius a N(0, 1 cm)
# step reflected into the ring. Guesses: it wanders all round within some 100 episodes, and one
# episode's move is a fraction of the ring, as ArmBalls' distractor moves a fraction of its
# square per episode (docs/armballs.md).
DISTRACTOR_STEP = 0.5  # rad
DISTRACTOR_RADIUS_STEP = 0.01  # m
PHYSICAL = False  # nothing physical attached: any host can run it
# The twin's load watchdog holds 5 s at over 0.9 of the maximum torque before it stops the run
# (a real arm's: 2 s, robot/watchdog.py). The twin's invisible guard above the wall keeps the
# ball in where the real ball would leave the arena (sim/models/make_scene.py), and a ball
# wedged between the arm and the guard held the arm at full load for 2.5 s before it slid up
# and free (measured 2026-12-01: rge-sae, seed 100, episode 152, joints 3 and 5; the 2 s
# watchdog stopped that run, and its resume replayed the same episode into the same stop). The
# twin's servos do not heat; 5 s is longer than an episode's return and settle cap (1 + 3 s),
# so a wedge the twin frees by itself passes and an arm that stays stuck is still stopped.
TWIN_WATCHDOG_HOLD_S = 5.0


@dataclass(frozen=True)
class Options(VideoOptions):
    """Options of the twin rig (and ``record_video``: ``explore.rigs.video``).

    Attributes:
        render_size: [height, width] of the overhead frame, pixels (default 240 x 240; with the
            ground truth the outcome image is rendered at its own size and no frame is taken).
        ball: ``truth`` (default: the twin's ground truth) or ``tracker`` (the ball tracker on
            the overhead frames, as on a real rig, with the camera's exact arena model).
        ball_reset: ``none`` (default: the ball stays where the last episode left it, as on the
            real rig) or ``start`` (put back at its start position before every episode, as in
            the paper's simulated ArmBall, where the context never changes).
        render_quality: ``chosen`` (default: the scene's own settings, docs/twin.md) or
            ``legacy`` (MuJoCo's default quality and full frames reduced to the observation,
            the twin's images before 2026-12-01); ``sim.RENDER_QUALITIES``.
        distractor: ``none`` (default) or ``walk``: a second ball (red) that the arm cannot
            move, taking a random step on the ball's ring before every episode
            (``distractor_walk``).
        distractor_step: the standard deviation of the walk's angle step, rad, in [0, pi]
            (default ``DISTRACTOR_STEP``).
        watchdog_hold_s: how long a joint may stay over the watchdog's load limit before the
            run stops, s (default ``TWIN_WATCHDOG_HOLD_S``).
    """

    render_size: tuple[int, int] = field(default=(240, 240), metadata={"expected": RENDER_SIZE})
    ball: Literal["truth", "tracker"] = "truth"
    ball_reset: Literal["none", "start"] = "none"
    render_quality: str = "chosen"
    distractor: Literal["none", "walk"] = "none"
    distractor_step: float = field(
        default=DISTRACTOR_STEP, metadata={"expected": "radians in [0, pi]"}
    )
    watchdog_hold_s: float = field(
        default=TWIN_WATCHDOG_HOLD_S, metadata={"expected": "seconds > 0"}
    )

    def __post_init__(self) -> None:
        super().__post_init__()
        lo, hi = RENDER_SIDE
        if not all(lo <= side <= hi for side in self.render_size):
            raise BadOption("render_size", f"must be {RENDER_SIZE}, got {list(self.render_size)}")
        if not self.watchdog_hold_s > 0:
            raise BadOption("watchdog_hold_s", f"must be seconds > 0, got {self.watchdog_hold_s}")
        if not 0 <= self.distractor_step <= math.pi:
            raise BadOption(
                "distractor_step", f"must be radians in [0, pi], got {self.distractor_step}"
            )
        if self.render_quality not in RENDER_QUALITIES:
            raise BadOption(
                "render_quality",
                f"must be one of {', '.join(RENDER_QUALITIES)}, got {self.render_quality!r}",
            )


def make_rig(config: RigConfig, options: Options) -> Rig:
    """The twin rig (unconnected) with ``options``."""
    walk = options.distractor == "walk"
    scene = SCENE_DISTRACTOR if walk else SCENE
    twin = Twin(
        scene, render_size=options.render_size, render_quality=options.render_quality,
        servos=rig_servos(config),
    )  # fmt: skip
    camera = SimCamera(twin)
    locator = tracker_locator(twin_arena_model(camera)) if options.ball == "tracker" else None
    reset = options.ball_reset == "start"

    def before_episode(rng: np.random.Generator) -> None:
        if reset:
            twin.place_ball()
        if walk:
            xy = twin.distractor_position()[:2]
            twin.place_distractor(distractor_walk(xy, options.distractor_step, rng))

    return Rig(
        arm=SimArm(twin, watchdog=Watchdog(hold_s=options.watchdog_hold_s)), camera=camera,
        clock=TwinClock(twin), config=config, twin=twin,
        ball_locator=locator,
        before_episode=before_episode if reset or walk else None,
        # with the ground truth, the outcome image is all a frame is for: render it at its size
        square_view=(
            (lambda side: camera.read_square(side).image)
            if locator is None and options.render_quality == "chosen"
            else None  # legacy: reduced from the full frame, as those images were made
        ),
        video_frame=(
            (lambda: camera.read_square(options.record_video).image)
            if options.record_video
            else None
        ),
    )  # fmt: skip


def rig_servos(config: RigConfig):
    """The twin's servos for ``config.rig_id``: its fitted ``dynamics.json`` (``ergo calibrate
    dynamics``) when there is one, else None (the nominal twin's); a bad file is a RigError."""
    from calibration.store import CalibrationError
    from sim.servo_model import fitted_servos

    try:
        return fitted_servos(config.rig_id)[0]
    except CalibrationError as exc:
        raise RigError(f"{exc} (a damaged twin calibration is not ignored)") from None


def scene(config: RigConfig, options: Options) -> Scene:
    """The twin's scene: the Ergo Jr arena, with the distractor when it walks."""
    return replace(TWIN_ARENA, distractor=options.distractor == "walk")


def distractor_walk(xy: np.ndarray, step: float, rng: np.random.Generator) -> np.ndarray:
    """One step of the distractor's random walk from ``xy`` (2,) m: the new (x, y), m."""
    from explore.learner.goal_spaces import R_MAX, R_MIN

    r = float(np.hypot(*xy)) + rng.normal(0.0, DISTRACTOR_RADIUS_STEP)
    span = R_MAX - R_MIN
    r = R_MIN + span - abs(span - abs(r - R_MIN) % (2 * span))  # reflected into the ring
    t = float(np.arctan2(xy[1], xy[0])) + rng.normal(0.0, step)
    return np.array([r * np.cos(t), r * np.sin(t)])
