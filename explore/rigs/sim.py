"""The ``sim`` rig: the MuJoCo twin in-process (SimArm + SimCamera + TwinClock)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any, Literal

import numpy as np

from explore.learner.scene import Scene
from explore.options import BadOption
from explore.rigs.arena import R_MAX, R_MIN, TWIN_ARENA
from explore.rigs.ball import TwinSensor, tracker_locator
from explore.rigs.clock import TwinClock
from explore.rigs.rig import Rig, RigConfig, RigError
from explore.rigs.video import VideoOptions
from robot.watchdog import Watchdog
from sim.arm import SimArm
from sim.camera import SimCamera
from sim.models.make_scene import ARENA_RADIUS
from sim.twin import SCENE, SCENE_DISTRACTOR, Twin

# Rendered frame side, pixels: below 16 the tracker has nothing to see, above 2048 a software
# render takes seconds (guesses, on the safe side).
RENDER_SIDE = (16, 2048)
RENDER_SIZE = f"[height, width], integers in [{RENDER_SIDE[0]}, {RENDER_SIDE[1]}]"
# The distractor's walk before each episode, on the ring where the ball's centre lies
# (explore/rigs/arena.py R_MIN..R_MAX): its angle takes a N(0, step) step, 0.5 rad by
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
# The history fsyncs at most once a second (``Rig.sync_interval_s``), as ArmBalls' does
# (explore/rigs/armballs.py): an fsync cost 3-5 ms an episode on the development machine
# (cProfile, 180 rge-efr episodes: 0.5-0.8 s of fsync), a third of a 15 ms twin episode and
# more than the outcome frame; a SIGKILL loses nothing (the records are in the page cache), a
# power cut at most the last second of episodes, which the resume detects (``history.synced``)
# and plays again to the same records (the twin is deterministic). A real arm's rig keeps one
# fsync per episode: its episodes cannot be played again.
TWIN_SYNC_INTERVAL_S = 1.0


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
        render_quality: ``chosen``, the only value (the scene's own settings, docs/twin.md),
            kept so that run folders that name it still open; ``legacy`` (MuJoCo's default
            quality, the images before 2026-12-01) was removed: no current result needs it
            (the results made with it are in git history).
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
        if self.render_quality != "chosen":
            raise BadOption(
                "render_quality",
                f"must be 'chosen', got {self.render_quality!r} (the legacy render mode was "
                "removed: no current result needs it)",
            )


def make_rig(config: RigConfig, options: Options) -> Rig:
    """The twin rig (unconnected) with ``options``."""
    walk = options.distractor == "walk"
    scene = SCENE_DISTRACTOR if walk else SCENE
    twin = Twin(
        scene, render_size=options.render_size, servos=rig_servos(config),
    )  # fmt: skip
    camera = SimCamera(twin)
    locator = tracker_locator(twin_arena_model(camera)) if options.ball == "tracker" else None
    reset = options.ball_reset == "start"

    def prepare(rng: np.random.Generator) -> None:
        if reset:
            twin.place_ball()
        if walk:
            xy = twin.distractor_position()[:2]
            twin.place_distractor(distractor_walk(xy, options.distractor_step, rng))

    sensor = TwinSensor(twin, camera, locator, prepare=prepare if reset or walk else None)
    return Rig(
        arm=SimArm(twin, watchdog=Watchdog(hold_s=options.watchdog_hold_s)), camera=camera,
        clock=TwinClock(twin), config=config, sensor=sensor, sync_interval_s=TWIN_SYNC_INTERVAL_S,
        video_frame=(
            (lambda: camera.read_square(options.record_video).image)
            if options.record_video
            else None
        ),
    )  # fmt: skip


def twin_arena_model(camera: Any) -> Any:
    """The exact ``ArenaModel`` of a twin ``SimCamera`` (its known projection, no calibration
    error), over the arena's bounding square."""
    from vision.rectify import (
        ArenaModel,
        estimate_camera_position,
        fit_homography,
        undistort_points,
    )

    k, d = camera.intrinsics()
    h = ARENA_RADIUS
    xy = np.array([[x, y] for x in (-h, 0.0, h) for y in (-h, 0.0, h)])
    px = camera.project(np.column_stack([xy, np.zeros(len(xy))]))
    homography = fit_homography(undistort_points(px, k, d), xy)
    position = estimate_camera_position(px, xy, k, d)
    size = (camera.size[1], camera.size[0])  # (width, height)
    return ArenaModel(k, d, size, homography, np.zeros(2), h, position)


def rig_servos(config: RigConfig):
    """The twin's servos for ``config.rig_id``: its fitted ``dynamics.json``
    (``RigConfig.resolved``) (``ergo calibrate dynamics``) when there is one, else None (the nominal
    twin's); a bad file is a RigError."""
    from calibration.store import CalibrationError
    from sim.servo_model import fitted_servos

    try:
        return fitted_servos(config.resolved().calibration)[0]
    except CalibrationError as exc:
        raise RigError(f"{exc} (a damaged twin calibration is not ignored)") from None


def scene(config: RigConfig, options: Options) -> Scene:
    """The twin's scene: the Ergo Jr arena, with the distractor when it walks."""
    return replace(TWIN_ARENA, distractor=options.distractor == "walk")


def distractor_walk(xy: np.ndarray, step: float, rng: np.random.Generator) -> np.ndarray:
    """One step of the distractor's random walk from ``xy`` (2,) m: the new (x, y), m. The
    C library's scalar functions (numpy's arctan2 runs a SIMD version chosen by CPU)."""
    x, y = float(xy[0]), float(xy[1])
    r = math.sqrt(x * x + y * y) + rng.normal(0.0, DISTRACTOR_RADIUS_STEP)
    span = R_MAX - R_MIN
    r = R_MIN + span - abs(span - abs(r - R_MIN) % (2 * span))  # reflected into the ring
    t = math.atan2(y, x) + rng.normal(0.0, step)
    return np.array([r * math.cos(t), r * math.sin(t)])
