"""``ErgoJrScripted``: a teleoperator that needs no hands, keyboard or display
(``ergo_jr_scripted``), for headless tests and demos.

From ``connect`` on, it plays motions one after the other, each drawn from its seed: from the
rest pose to the first point of a motor primitive (the Ergo Jr's DMPs over the exploration's
joint ranges, ``explore.rigs.motor.ergo_jr_dmp``, 48 parameters uniform in [-1, 1]: what
``ergo explore --strategy rpe`` plays), the primitive itself, back to rest, a pause; each part
slowed down so that no joint moves faster than ``max_speed``. ``get_action`` gives the goal
positions at the wall time since ``connect``, linearly interpolated between the motion's points,
rad: the same motions at any loop rate.
"""

from __future__ import annotations

import time
from functools import cached_property
from typing import Any

import numpy as np
from lerobot.teleoperators.teleoperator import Teleoperator
from lerobot.utils.errors import DeviceAlreadyConnectedError, DeviceNotConnectedError
from lerobot_robot_ergo_jr.features import action_features, joints_dict

from explore.learner.dmp import N_PARAMS
from explore.rigs.motor import ergo_jr_dmp
from lerobot_teleoperator_ergo_jr.config_ergo_jr_teleop import ErgoJrScriptedConfig
from robot.spec import ergo_jr_spec


class MotionScript:
    """The motions of a seed as a function of time (see the module docstring).

    Args:
        seed: the motions' seed.
        lead_s, return_s, pause_s: the least time to a motion's start, back to rest, and the
            pause at rest, s.
        max_speed: the fastest any joint moves, rad/s.
    """

    def __init__(
        self, seed: int, lead_s: float, return_s: float, pause_s: float, max_speed: float
    ) -> None:
        self.rng = np.random.default_rng(seed)
        self.dmp = ergo_jr_dmp()
        self.rest = ergo_jr_spec().rest
        self.lead_s, self.return_s, self.pause_s = lead_s, return_s, pause_s
        self.max_speed = max_speed
        self._times = np.zeros(0)  # keyframe times, s, increasing
        self._points = np.zeros((0, len(self.rest)))  # (k, 6) rad

    def _extend(self) -> None:
        """Add the next motion's keyframes."""
        start = self._times[-1] if len(self._times) else 0.0
        path = self.dmp.trajectory(self.rng.uniform(-1.0, 1.0, N_PARAMS))  # (n, 6) rad
        points = np.vstack([self.rest, path, self.rest])
        steps = np.abs(np.diff(points, axis=0)).max(axis=1) / self.max_speed  # (n + 1,) s
        steps[1:-1] = np.maximum(steps[1:-1], 1.0 / self.dmp.config.rate_hz)
        steps[0] = max(steps[0], self.lead_s)
        steps[-1] = max(steps[-1], self.return_s)
        t = start + np.concatenate([[0.0], np.cumsum(steps)])
        times = np.concatenate([t, [t[-1] + self.pause_s]])
        points = np.vstack([points, self.rest])
        if len(self._times):  # the first keyframe is the previous motion's last
            times, points = times[1:], points[1:]
        self._times = np.concatenate([self._times, times])
        self._points = np.vstack([self._points, points])

    def at(self, t: float) -> np.ndarray:
        """The goal positions at ``t`` s from the start, shape (6,), rad."""
        while not len(self._times) or self._times[-1] < t:
            self._extend()
        first = int(np.searchsorted(self._times, t)) - 1  # keyframes before it are done with
        if first > 0:
            self._times, self._points = self._times[first:], self._points[first:]
        return np.array([np.interp(t, self._times, p) for p in self._points.T])


class ErgoJrScripted(Teleoperator):
    """Scripted motions as a teleoperator (see the module docstring)."""

    config_class = ErgoJrScriptedConfig
    name = "ergo_jr_scripted"

    def __init__(self, config: ErgoJrScriptedConfig) -> None:
        super().__init__(config)
        self.config = config
        self.script: MotionScript | None = None
        self._t0 = 0.0

    @cached_property
    def action_features(self) -> dict[str, type]:
        return action_features()

    @cached_property
    def feedback_features(self) -> dict[str, type]:
        return {}

    @property
    def is_connected(self) -> bool:
        return self.script is not None

    @property
    def is_calibrated(self) -> bool:
        return True

    def calibrate(self) -> None:
        """Nothing to calibrate."""

    def connect(self, calibrate: bool = True) -> None:
        if self.is_connected:
            raise DeviceAlreadyConnectedError(f"{self} is already connected")
        c = self.config
        self.script = MotionScript(c.seed, c.lead_s, c.return_s, c.pause_s, c.max_speed)
        self._t0 = time.monotonic()

    def configure(self) -> None:
        """Nothing to set."""

    def get_action(self) -> dict[str, float]:
        if self.script is None:
            raise DeviceNotConnectedError(f"{self} is not connected")
        return joints_dict(self.script.at(time.monotonic() - self._t0))

    def send_feedback(self, feedback: dict[str, Any]) -> None:
        """It takes no feedback."""

    def disconnect(self) -> None:
        self.script = None
