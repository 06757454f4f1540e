"""One episode on a rig with an arm: rest pose, context, the motor primitive at the control rate,
back to rest, settle, outcome: ``EpisodeRunner``, the ``explore.rigs.episodes.EpisodePlayer`` of
every rig with an arm to drive (the twin and the physical rigs alike: where the ball is, is the
rig's ``BallSensor``'s to say, ``explore.rigs.ball``).

The outcome is observed with the arm back at its rest pose (upright, over the arena's centre),
so that the arm hides no part of the ring and the outcome image varies with the ball alone; the
next episode's context is the same scene. The original implementation observed the outcome with
the arm where its movement ended: there the arm's pose dominated the image, and a VAE trained on
such images encoded the arm, not the ball (measured on the earlier twin: docs/notebook.md, in git).

All positions in metres (arena frame: origin at the arm's base, z up), angles in radians,
durations in seconds.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from explore.learner.dmp import MotorPrimitive
from explore.learner.experience import Observation
from explore.rigs.ball import BallSensor
from explore.rigs.clock import Clock
from explore.rigs.episodes import EpisodeConfig, EpisodeResult
from plumbing.fixed_order import distance
from robot.arm import Arm


class ArmRig(Protocol):
    """What ``EpisodeRunner`` takes of a rig: ``explore.rigs.rig.Rig`` is one (this module does
    not import it: ``Rig.episodes`` imports this one)."""

    arm: Arm | None
    clock: Clock | None
    sensor: BallSensor | None
    motor: MotorPrimitive
    video_frame: Callable[[], np.ndarray] | None


@dataclass
class Movement:
    """What playing a motor primitive produced (``EpisodeRunner.play``).

    Attributes:
        targets: commands sent, (T, n_joints) rad. measured: joints read at the end of each
        tick, (T, n_joints) rad. end_effector: tool tip at each tick, (T, 3) m (NaN: unknown).
        start_positions: joints read before the first command, (n_joints,) rad. frames: the
        camera at the start of each tick, (T, side, side, 3) BGR uint8, or None.
    """

    targets: np.ndarray
    measured: np.ndarray
    end_effector: np.ndarray
    start_positions: np.ndarray
    frames: np.ndarray | None = None


MOVED_THRESHOLD = 0.01  # m: a ball displacement under 1 cm is not "moved" (guess: tracker noise)


__all__ = ["MOVED_THRESHOLD", "EpisodeResult", "EpisodeRunner"]


class EpisodeRunner:
    """Runs episodes on a rig's arm with its motor primitive (``rig.motor``, or ``motor``): the
    ``explore.rigs.episodes.EpisodePlayer`` of every rig with an arm to drive."""

    def __init__(
        self, rig: ArmRig, motor: MotorPrimitive | None = None, config: EpisodeConfig | None = None
    ) -> None:
        self.rig = rig
        self.motor = motor if motor is not None else rig.motor
        self.config = config or EpisodeConfig()
        self.dt = 1.0 / self.config.rate_hz

    # ---- phases --------------------------------------------------------------------------
    def go_rest(self) -> None:
        """Move to the rest pose by linear interpolation over ``reset_s`` at the control rate.

        Nothing is sent when the last command already was the rest pose.
        """
        arm, clock = self.rig.arm, self.rig.clock
        start = arm.last_sent
        rest = arm.spec.rest
        if start is not None and np.array_equal(start, rest):
            return
        if start is None:
            start = arm.read().positions
        n = max(1, round(self.config.reset_s / self.dt))
        # every tick's pose at once (the same bits as start + (rest - start) * (i / n))
        path = start + (rest - start) * (np.arange(1, n + 1)[:, None] / n)
        for q in path:
            arm.command(q)
            clock.advance(self.dt)

    def observe(self, render: bool = True) -> Observation:
        """Where the ball is (the rig's sensor), with the observation image if ``render``."""
        return self.rig.sensor.locate(self.config.obs_size if render else None)

    def play(self, theta: np.ndarray) -> Movement:
        """Play the motor primitive of ``theta`` (n_params,) at the control rate: at each tick
        the camera frame (with the rig's ``video_frame``), the command, the clock, the reading."""
        traj = self.motor.trajectory(theta)
        arm, clock, sensor = self.rig.arm, self.rig.clock, self.rig.sensor
        capture = self.rig.video_frame
        t = len(traj)
        n = arm.spec.n
        sent = np.empty((t, n))
        measured = np.empty((t, n))
        ee = np.full((t, 3), np.nan)
        frames = [] if capture is not None else None
        start = arm.read().positions
        for i, q in enumerate(traj):
            if frames is not None:
                frames.append(capture())
            sent[i] = arm.command(q)
            clock.advance(self.dt)
            measured[i] = arm.read().positions
            ee[i] = sensor.tool_tip()
        video = np.stack(frames) if frames else None
        return Movement(sent, measured, ee, np.asarray(start, dtype=float), video)

    def settle(self) -> float:
        """Wait until the ball is still and the arm has stopped at rest; returns the time
        waited, s (at least one ``settle_check_s``: the arm's speed takes two readings).

        The arm lags its last rest command by 1-2 degrees per joint on the twin, which shifts
        it by a few pixels in the 64x64 outcome image, more than a ball moved by a centimetre
        does; it stops within 0.2-0.3 s (measured, docs/twin.md). Ball, twin: its true speed.
        Ball, real rigs: the tracked position between two frames ``settle_check_s`` apart (a
        ball not seen in both counts as still moving, up to the ``settle_max_s`` cap, as the
        original waited and re-observed).
        """
        cfg, clock, sensor, arm = self.config, self.rig.clock, self.rig.sensor, self.rig.arm
        sensor.watch()
        joints = arm.read().positions
        # a joint is still when it moved less than arm_settle_speed allows, or by at most one
        # unit of its reading (a real servo's reading can flicker by one unit at rest)
        step_max = np.maximum(
            cfg.arm_settle_speed * cfg.settle_check_s, arm.position_resolution * (1 + 1e-6)
        )
        waited = 0.0
        while waited < cfg.settle_max_s:
            clock.advance(cfg.settle_check_s)
            waited += cfg.settle_check_s
            now = arm.read().positions
            arm_still = bool(np.all(np.abs(now - joints) <= step_max))
            joints = now
            ball_still = sensor.still(cfg.settle_speed, cfg.settle_check_s)
            if ball_still and arm_still:
                break
        return waited

    # ---- the whole episode -----------------------------------------------------------------
    def context(self, scene_rng: np.random.Generator, render: bool) -> Observation:
        """Go to the rest pose, let the rig's sensor change the scene (``BallSensor.prepare``:
        the twin's ball reset, the distractor's walk) and observe the context there."""
        self.go_rest()
        self.rig.sensor.prepare(scene_rng)
        return self.observe(render=render)

    def run(self, theta: np.ndarray, context: Observation) -> EpisodeResult:
        """Play ``theta`` from the rest pose (``context`` seen there), go back to rest, wait for the
        ball to settle, then observe the outcome."""
        move = self.play(theta)
        self.go_rest()
        settle_s = self.settle()
        outcome = self.observe(render=True)
        moved = bool(
            np.all(np.isfinite(context.ball))
            and np.all(np.isfinite(outcome.ball))
            and distance(outcome.ball, context.ball) > MOVED_THRESHOLD
        )
        return EpisodeResult(
            move.targets, move.measured, move.end_effector, outcome, settle_s, moved,
            start_positions=move.start_positions, frames=move.frames,
        )  # fmt: skip
