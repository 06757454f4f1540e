"""The ``armballs`` and ``arm2balls`` rigs: ArmBalls and Arm-2-Balls of the CoRL 2018 campaign
(sim/armballs, docs/armballs.md), a planar 7-joint arm that can catch a ball, with (arm2balls)
or without (armballs) a distractor that takes a random walk.

Unlike the Ergo Jr rigs there is no arm to drive, camera to read or clock to step: the whole
episode is simulated at once (``ArmBallsPlayer``, the rig's ``player``), from the same scene
every time (the original resets the ball, the distractor and the arm before each episode):
context, 49 RBF motor parameters, the outcome after 50 steps. What a record holds:

- ``theta``: the 49 parameters (joint-major, ``sim.armballs.RbfPrimitive``);
- ``targets`` = ``measured``: the joints' relative angles at each step, pi x the commands
  (T = 50, 7) rad (the kinematics have no lag to measure);
- ``end_effector``: the hand at each step, (50, 3), z = 0, in units of the arm's reach;
- ``ball``, ``distractor`` (arm2balls; NaN without), ``context_ball``, ``context_distractor``:
  positions in the square [-1, 1]^2 (the rig's ``Scene``: ``ARM_BALLS_SQUARE``);
- ``image``: the 64 x 64 observation of the final scene, BGR (the renderer draws RGB);
- ``ball_moved``: the arm caught the ball (the only way the ball moves);
- ``settle_s`` 0, ``sim_state`` empty (nothing carries over between episodes).

The distractor's walk draws from the episode's own scene stream (``default_rng([seed,
episode, 1])``, given to ``ArmBallsPlayer.context``), apart from the strategy's, so a run is
a function of its seed and a resumed run draws what the uninterrupted one would have.
"""

from __future__ import annotations

import dataclasses
import math
import sys
from dataclasses import dataclass
from typing import Any

import numpy as np

from explore.learner.experience import Observation
from explore.learner.scene import Scene
from explore.options import BadOption
from explore.rigs.episodes import EpisodeResult
from explore.rigs.rig import Rig, RigConfig
from sim.armballs import ARM_2_BALLS, ARM_BALLS, ArmBallsConfig, ArmBallsEnv, render_scene
from sim.armballs.env import initial_state

PHYSICAL = False  # nothing physical attached: any host can run it
# The rig names of this module, and the environment each stands for (sim/armballs/config.py).
ENVIRONMENTS = {"armballs": ARM_BALLS, "arm2balls": ARM_2_BALLS}
# History fsyncs at most once a second (``Rig.sync_interval_s``): an fsync takes about 2 ms on
# the development machine (measured: 300 appends of 5 kB, 2.07 ms each), an ArmBalls episode
# about 0.3 ms of computing (docs/armballs.md); a SIGKILL loses nothing (the records are in the
# page cache), a power cut at most the last second of episodes, which the resume detects
# (``history.synced``, explore/runs/store.py) and redoes in about a second. The interval: a guess.
SYNC_INTERVAL_S = 1.0
NO_POSITION = np.full(2, np.nan)

#: ArmBalls: the square [-1, 1]^2 in units of the arm's reach (the links sum to 1), reset before
#: every episode (docs/armballs.md).
ARM_BALLS_SQUARE = Scene(
    name="the ArmBalls square",
    unit="reach",
    ball_half_width=1.0,
    hand_half_width=1.0,
    ring=None,
    resets=True,
)
#: Arm-2-Balls: the same square with the distractor.
ARM_2_BALLS_SQUARE = dataclasses.replace(
    ARM_BALLS_SQUARE, name="the Arm-2-Balls square", distractor=True
)


@dataclass(frozen=True)
class Options:
    """Options of the ArmBalls rigs; every other setting is the published campaign's
    (sim/armballs/config.py, docs/armballs.md).

    Attributes:
        distractor_noise: standard deviation of the distractor's step, per step and axis
            (arm2balls; default 0.1, the learning runs'; the published RPE runs also used 0.5).
    """

    distractor_noise: float = ARM_2_BALLS.distractor_noise

    def __post_init__(self) -> None:
        if not 0.0 <= self.distractor_noise <= 2.0:
            raise BadOption(
                "distractor_noise", f"must be a number in [0, 2], got {self.distractor_noise}"
            )


def environment(config: RigConfig, options: Options) -> ArmBallsConfig:
    """The environment the rig ``config.name`` stands for, with ``options``."""
    return dataclasses.replace(ENVIRONMENTS[config.name], distractor_noise=options.distractor_noise)


def scene(config: RigConfig, options: Options) -> Scene:
    """The rig's scene: the square [-1, 1]^2, reset before every episode."""
    return ARM_2_BALLS_SQUARE if ENVIRONMENTS[config.name].distractor else ARM_BALLS_SQUARE


class RbfMotor:
    """ArmBalls' motor primitive as the rig's ``MotorPrimitive``: 49 parameters -> the joints'
    relative angles, pi x the RBF commands, shape (50, 7), rad."""

    def __init__(self, env: ArmBallsEnv) -> None:
        self.primitive = env.primitive
        self.n_params = env.n_params

    def trajectory(self, theta: np.ndarray) -> np.ndarray:
        return math.pi * self.primitive.commands(theta)


def to_bgr(rgb: np.ndarray) -> np.ndarray:
    """An RGB image (H, W, 3) uint8 as BGR, the order records and datasets keep."""
    return np.ascontiguousarray(rgb[..., ::-1])


class ArmBallsPlayer:
    """Plays ArmBalls episodes for the exploration loop (``explore.rigs.episodes``).

    Args:
        env: the environment (its image size is the run's observation size).
    """

    def __init__(self, env: ArmBallsEnv) -> None:
        self.env = env
        self.start = initial_state(env.config)
        self._scene_rng: np.random.Generator | None = None

    def context(self, scene_rng: np.random.Generator, render: bool) -> Observation:
        """The scene every episode starts from; ``scene_rng`` draws this episode's walk."""
        self._scene_rng = scene_rng
        s = self.start
        distractor = NO_POSITION if s.distractor is None else s.distractor.copy()
        image = (
            to_bgr(render_scene(s.ball, s.distractor, config=self.env.config)) if render else None
        )
        return Observation(ball=s.ball.copy(), image=image, distractor=distractor)

    def run(self, theta: np.ndarray, context: Observation) -> EpisodeResult:
        if self._scene_rng is None:
            raise RuntimeError("ArmBallsPlayer.run before context: no scene stream")
        out = self.env.play(theta, self._scene_rng, render=True)
        self._scene_rng = None
        angles = math.pi * out.commands  # (T, 7) rad
        hand = np.zeros((len(angles), 3))
        hand[:, :2] = out.paths.hand[0]
        outcome = Observation(
            ball=out.ball,
            image=to_bgr(out.image),  # type: ignore[arg-type]
            distractor=NO_POSITION if out.distractor is None else out.distractor,
        )
        return EpisodeResult(angles, angles, hand, outcome, settle_s=0.0, ball_moved=out.caught)

    def go_rest(self) -> None:
        """Nothing to do: the next episode starts from the reset scene."""


def make_rig(config: RigConfig, options: Options) -> Rig:
    """The ArmBalls rig ``config.name`` (no arm, camera or clock: its player)."""
    env = ArmBallsEnv(environment(config, options))

    def player(episode_config: Any) -> ArmBallsPlayer:
        size = int(getattr(episode_config, "obs_size", env.config.image_size))
        return ArmBallsPlayer(ArmBallsEnv(dataclasses.replace(env.config, image_size=size)))

    return Rig(config=config, motor=RbfMotor(env), player=player, sync_interval_s=SYNC_INTERVAL_S)


# ---- the outcome database -------------------------------------------------------------------
def outcome_dataset(
    config: RigConfig, options: Options, n: int, seed: int = 0, progress: bool = False
) -> dict[str, np.ndarray]:
    """``n`` scenes for pre-training representations, as the published campaign's database
    (this project's paper, appendix "Results on Arm-2-Balls": the positions of both balls
    uniform over [-1, 1]^4): the ball, and on arm2balls the distractor, uniform over the square
    independently, drawn as an episode's outcome is (no arm).

    Returns:
        images: (n, 64, 64, 3) BGR uint8; ball: (n, 2); with the distractor also
        distractor: (n, 2), in the square [-1, 1]^2.
    """
    env = environment(config, options)
    rng = np.random.default_rng(seed)
    ball = rng.uniform(-1.0, 1.0, (n, 2))
    others = rng.uniform(-1.0, 1.0, (n, 2)) if env.distractor else None
    size = env.image_size
    images = np.empty((n, size, size, 3), dtype=np.uint8)
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=n, unit="img", file=sys.stderr, mininterval=1.0, desc="outcomes")
    try:
        for i in range(n):
            d = None if others is None else others[i]
            images[i] = to_bgr(render_scene(ball[i], d, config=env))
            if bar is not None:
                bar.update(1)
    finally:
        if bar is not None:
            bar.close()
    out = {"images": images, "ball": ball}
    if others is not None:
        out["distractor"] = others
    return out
