"""How a rig plays episodes: what an episode produced (``EpisodeResult``) and the
``EpisodePlayer`` protocol the exploration loop drives.

A rig with an arm to drive plays its episodes with ``explore.runs.episode.EpisodeRunner``
(rest pose, context, the motor primitive at the control rate, back to rest, settle, outcome). A
rig that simulates a whole episode at once (ArmBalls: no arm, camera or clock to step) gives its
own player (``Rig.player``); the loop cannot tell them apart.

Units: the rig's (``explore.learner.scene.Scene.unit``): metres on the Ergo Jr rigs, the arm's
reach on ArmBalls; angles in radians, durations in seconds.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from explore.learner.experience import Observation


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
