"""Discrete dynamic movement primitives: 48 parameters in [-1, 1] -> a 6-joint trajectory.

One DMP per joint, 7 Gaussian basis functions and one goal each (the paper's rig,
docs/facts.md). Vectorised over joints.

Arithmetic: ``plumbing.fixed_order``'s exp, log and sums in a fixed order, never BLAS or numpy's
SIMD exp, so a trajectory is the same bits on every machine (docs/determinism.md).

Constants from the original implementation (flowersteam/APEX ``poppimage``, read for facts):
weights scaled by 200, goals by 1, 40 points at dt = 1/40 s, alpha_y = 25, beta_y = alpha_y / 4,
canonical system x' = -x, centres exp(-linspace(0.8, 0, 7)), widths 8 n^2 / c^1.5,
forcing x (psi . w) / sum(psi), start y0 = 0. Unlike the original (which dropped dy from the
integration, a bug), the system is integrated properly with semi-implicit Euler sub-steps.

The normalised trajectory is clipped to [-1, 1] and mapped linearly, per joint, onto the
joint ranges of ``DmpConfig`` (radians), which the rig gives: the Ergo Jr rigs' are
``explore.rigs.motor.ERGO_JR_LOWER`` / ``ERGO_JR_UPPER``, chosen for the arena.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from plumbing import fixed_order

N_JOINTS = 6
N_BASIS = 7
N_PARAMS = N_JOINTS * (N_BASIS + 1)  # 48

WEIGHT_SCALE = 200.0  # original implementation
GOAL_SCALE = 1.0  # original implementation
ALPHA_Y = 25.0  # original implementation
BETA_Y = ALPHA_Y / 4.0  # critically damped
ALPHA_X = 1.0  # canonical system x' = -x (original)
# The primitive's own time base: 40 points at dt = 1/40 s (original implementation); a rig plays
# the points at its control rate (``explore.runs.config.EpisodeConfig.rate_hz``, 40 Hz on the
# Ergo Jr, robot/spec.py).
RATE_HZ = 40.0


@dataclass(frozen=True)
class DmpConfig:
    """DMP settings.

    Attributes:
        lower, upper: joint angles that -1 and +1 map to, shape (6,), rad (the rig's).
        n_points: trajectory points (played at ``rate_hz``).
        rate_hz: control rate, Hz (the trajectory lasts n_points / rate_hz seconds).
        substeps: integration sub-steps per point.
    """

    lower: tuple[float, ...]
    upper: tuple[float, ...]
    n_points: int = 40
    rate_hz: float = RATE_HZ
    substeps: int = 10

    @property
    def duration(self) -> float:
        """Trajectory length, s."""
        return self.n_points / self.rate_hz


class MotorPrimitive(Protocol):
    """What turns motor parameters into a joint trajectory; a rig owns one (``Rig.motor``) and
    strategies propose ``n_params`` numbers in [-1, 1] for it."""

    n_params: int

    def trajectory(self, theta: np.ndarray) -> np.ndarray:
        """Motor parameters (n_params,) in [-1, 1] -> joint targets (T, n_joints), rad."""
        ...


class ParameterError(ValueError):
    """Motor parameters of the wrong shape, not finite, or outside [-1, 1]."""


def check_parameters(theta: np.ndarray) -> np.ndarray:
    """Validate motor parameters: shape (48,), finite, inside [-1, 1]. Returns a float copy."""
    theta = np.asarray(theta, dtype=float)
    if theta.shape != (N_PARAMS,):
        raise ParameterError(f"motor parameters have shape {theta.shape}, expected ({N_PARAMS},)")
    if not np.all(np.isfinite(theta)):
        raise ParameterError("motor parameters contain NaN or infinity")
    worst = float(np.max(np.abs(theta)))
    if worst > 1.0 + 1e-9:
        raise ParameterError(
            f"motor parameters must lie in [-1, 1]; got a value of magnitude {worst:.3g}"
        )
    return theta.copy()


class Dmp:
    """Six DMPs in parallel: the Ergo Jr's ``MotorPrimitive`` (``explore.rigs.motor`` gives it
    the rig's joint ranges)."""

    n_params = N_PARAMS

    def __init__(self, config: DmpConfig) -> None:
        self.config = config
        spread = np.linspace(0.8, 0.0, N_BASIS)
        self.centres = fixed_order.exp(-spread)  # shape (7,)
        self.widths = 8.0 * N_BASIS**2 * fixed_order.exp(1.5 * spread)  # / centres^1.5, (7,)
        self.lower = np.asarray(self.config.lower, dtype=float)
        self.upper = np.asarray(self.config.upper, dtype=float)
        if self.lower.shape != (N_JOINTS,) or self.upper.shape != (N_JOINTS,):
            raise ValueError("DmpConfig lower/upper must have 6 values each")
        self._goal_gain, self._basis_gain = self._linear_map()

    def _phase(self) -> np.ndarray:
        """Canonical phase x before each integration sub-step, shape (n_points * substeps,)."""
        cfg = self.config
        h = 1.0 / (cfg.rate_hz * cfg.substeps)
        steps = np.arange(cfg.n_points * cfg.substeps, dtype=float)
        return fixed_order.exp(steps * float(fixed_order.log(1.0 - h * ALPHA_X)))

    def _linear_map(self) -> tuple[np.ndarray, np.ndarray]:
        """The DMP with y0 = z0 = 0 is linear time-invariant in its input u = ab g + f, so the
        sampled trajectory is ``goal_gain * g + basis_gain @ w``.

        Semi-implicit Euler: z' = z + h (u - ab y - a z), y' = y + h z'.

        Returns:
            goal_gain: shape (n_points,); basis_gain: shape (n_points, 7).
        """
        cfg = self.config
        n_sub = cfg.n_points * cfg.substeps
        h = 1.0 / (cfg.rate_hz * cfg.substeps)
        a, ab = ALPHA_Y, ALPHA_Y * BETA_Y
        # impulse response of y to a unit u at step 0, steps 1..n_sub
        impulse = np.empty(n_sub)
        y, z = 0.0, 0.0
        u = 1.0
        for k in range(n_sub):
            z = z + h * (u - ab * y - a * z)
            y = y + h * z
            impulse[k] = y
            u = 0.0
        # y after step s (1-based) = sum_j impulse[s - 1 - j] u_j
        samples = np.arange(1, cfg.n_points + 1) * cfg.substeps  # (n_points,)
        lag = samples[:, None] - 1 - np.arange(n_sub)[None, :]  # (n_points, n_sub)
        conv = np.where(lag >= 0, impulse[np.clip(lag, 0, None)], 0.0)
        x = self._phase()
        gap = x[:, None] - self.centres[None, :]
        psi = fixed_order.exp(-self.widths[None, :] * (gap * gap))
        total = fixed_order.matmul(psi, np.ones(N_BASIS))  # the basis summed in order
        phi = x[:, None] * psi / total[:, None]  # (n_sub, 7)
        return ab * np.add.reduce(conv, axis=1), fixed_order.matmul(conv, phi)

    def normalised(self, theta: np.ndarray) -> np.ndarray:
        """Integrate the DMPs in normalised units (unclipped).

        Args:
            theta: shape (48,), in [-1, 1]: per joint 7 weights then 1 goal.

        Returns:
            shape (n_points, 6): y at t = dt, 2 dt, ..., n_points dt.
        """
        theta = check_parameters(theta).reshape(N_JOINTS, N_BASIS + 1)
        weights = theta[:, :N_BASIS] * WEIGHT_SCALE  # (6, 7)
        goal = theta[:, N_BASIS] * GOAL_SCALE  # (6,)
        # the basis summed in a fixed order, not by BLAS (the same bits on every machine)
        return self._goal_gain[:, None] * goal[None, :] + fixed_order.matmul(
            self._basis_gain, weights.T
        )

    def normalised_reference(self, theta: np.ndarray) -> np.ndarray:
        """The same integration step by step (slow; the tests compare it to ``normalised``)."""
        theta = check_parameters(theta).reshape(N_JOINTS, N_BASIS + 1)
        weights = theta[:, :N_BASIS] * WEIGHT_SCALE
        goal = theta[:, N_BASIS] * GOAL_SCALE
        cfg = self.config
        h = 1.0 / (cfg.rate_hz * cfg.substeps)
        y = np.zeros(N_JOINTS)
        z = np.zeros(N_JOINTS)
        out = np.empty((cfg.n_points, N_JOINTS))
        phase = self._phase()
        for i in range(cfg.n_points):
            for k in range(cfg.substeps):
                x = phase[i * cfg.substeps + k]
                psi = np.exp(-self.widths * (x - self.centres) ** 2)
                forcing = x * (weights @ psi) / psi.sum()
                z = z + h * (ALPHA_Y * (BETA_Y * (goal - y) - z) + forcing)
                y = y + h * z
            out[i] = y
        return out

    def trajectory(self, theta: np.ndarray) -> np.ndarray:
        """Joint trajectory, shape (n_points, 6), rad, inside [lower, upper] per joint."""
        y = np.clip(self.normalised(theta), -1.0, 1.0)
        return self.lower + (y + 1.0) * 0.5 * (self.upper - self.lower)
