"""How a rig plays episodes: their timing (``EpisodeConfig``), what an episode produced
(``EpisodeResult``) and the ``EpisodePlayer`` protocol the exploration loop drives.

A rig with an arm to drive plays its episodes with ``explore.rigs.arm_episodes.EpisodeRunner``
(rest pose, context, the motor primitive at the control rate, back to rest, settle, outcome),
asking its ``BallSensor`` where the ball is (``explore.rigs.ball``). A rig that simulates a whole
episode at once (ArmBalls: no arm, camera or clock to step) gives its own player; the loop asks
every rig for its player (``Rig.episodes``) and cannot tell them apart.

Units: the rig's (``explore.learner.scene.Scene.unit``): metres on the Ergo Jr rigs, the arm's
reach on ArmBalls; angles in radians, durations in seconds.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from explore.learner.experience import Observation
from robot.spec import CONTROL_RATE_HZ
from vision.observation import OBSERVATION_SIZE


@dataclass(frozen=True)
class EpisodeConfig:
    """Timing of an episode.

    Attributes:
        rate_hz: control rate (40 Hz: the DMP's 40 points last 1 s, as in the paper's rig).
        reset_s: time to go back to the rest pose (1 s, original implementation).
        settle_speed: the ball counts as still below this speed, m/s (guess: 1 cm/s).
        arm_settle_speed: the arm counts as back at rest when no joint moves faster than this,
            rad/s (guess, checked on the twin: it stops within 0.2-0.3 s). 0.05 rad/s over a
            0.1 s check is 0.286 degrees, just under one XL-320 position unit (0.293 degrees,
            datasheet), so a joint that moved by at most one unit of its reading
            (``Arm.position_resolution``) also counts as still: a reading that flickers by one
            unit at rest would otherwise hold every settle to ``settle_max_s``.
        settle_max_s: longest wait for the ball and the arm to settle (the original waited 3 s).
        settle_check_s: interval between two settle checks.
        obs_size: side of the square observation the representation sees, pixels (64, paper).
    """

    rate_hz: float = CONTROL_RATE_HZ
    reset_s: float = 1.0
    settle_speed: float = 0.01
    arm_settle_speed: float = 0.05
    settle_max_s: float = 3.0
    settle_check_s: float = 0.1
    obs_size: int = OBSERVATION_SIZE


@dataclass
class EpisodeResult:
    """Everything an episode produced.

    Attributes:
        targets: commands actually sent during the movement, shape (T, n_joints), rad.
        measured: joint positions read at the end of each tick, shape (T, n_joints), rad.
        end_effector: tool tip at each tick, shape (T, 3) (NaN where unknown).
        outcome: the observation after the ball settled.
        settle_s: how long the ball took to settle (or the cap).
        ball_moved: whether the episode moved the ball.
        start_positions: joint positions read just before the first command, (n_joints,) rad
            (empty where the rig has none to read: ArmBalls).
        frames: with the rig's ``video_frame``, the overhead camera at the start of each tick
            (before its command, when ``start_positions``/``measured[i - 1]`` were read), shape
            (T, side, side, 3) BGR uint8; else None.
    """

    targets: np.ndarray
    measured: np.ndarray
    end_effector: np.ndarray
    outcome: Observation
    settle_s: float
    ball_moved: bool
    extras: dict[str, float] = field(default_factory=dict)
    start_positions: np.ndarray = field(default_factory=lambda: np.zeros(0))
    frames: np.ndarray | None = None


class EpisodePlayer(Protocol):
    """What the exploration loop asks of a rig, episode by episode."""

    def context(self, scene_rng: np.random.Generator, render: bool) -> Observation:
        """Bring the scene to where an episode starts (the arm at rest, the rig's scene
        changes drawn from ``scene_rng``, the episode's own stream) and observe it; the image
        only if ``render``."""
        ...

    def run(self, theta: np.ndarray, context: Observation) -> EpisodeResult:
        """Play the motor parameters ``theta`` (n_params,) from ``context``; the outcome."""
        ...

    def go_rest(self) -> None:
        """Leave the arm at rest (the end of a session)."""
        ...
