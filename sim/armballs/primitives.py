"""Radial-basis motor primitives: a parameter vector in [-1, 1] -> a (T, n_joints) command path.

As in the original's RbfController (latentgoalexplo/actors/controllers.py, read for its
definition): each joint's command at step t is the weighted sum of ``n_rbf`` Gaussian bumps
shared by all joints, clipped to [-1, 1] (MyArmBalls.act clips the sequence). Bump k is centred
on step (k + 1) w + w // 4 with w = T // n_rbf: for the published T = 50 and n_rbf = 7 the centres
are steps 8, 15, 22, 29, 36, 43 and 50, so the last bump only rises within the episode. The
original builds the bumps by Gaussian-filtering unit impulses (scipy's default truncation at
4 sigma, i.e. a radius of int(4 sigma + 0.5) steps) and dividing by the peak: in closed form,
exp(-(t - c)^2 / (2 sigma^2)) within that radius and 0 beyond, which is what is computed here.

Parameters are laid out joint-major: index j * n_rbf + k weighs bump k of joint j.
"""

from __future__ import annotations

import numpy as np

from plumbing import fixed_order
from sim.armballs.config import ArmBallsConfig


class PrimitiveParameterError(ValueError):
    """Motor parameters of the wrong shape, not finite, or outside [-1, 1]."""


def rbf_centres(n_steps: int, n_rbf: int) -> np.ndarray:
    """Step index of each bump's peak, shape (n_rbf,)."""
    width = n_steps // n_rbf
    return (np.arange(1, n_rbf + 1) * width + width // 4).astype(float)


def rbf_basis(n_steps: int, n_rbf: int, sdev: float) -> np.ndarray:
    """The bumps sampled at steps 0..n_steps-1, shape (n_steps, n_rbf), peak value 1."""
    t = np.arange(n_steps, dtype=float)[:, None]
    d = t - rbf_centres(n_steps, n_rbf)[None, :]
    radius = int(4.0 * sdev + 0.5)  # scipy.ndimage.gaussian_filter1d's default truncation
    z = d / sdev
    return np.where(np.abs(d) <= radius, fixed_order.exp(-0.5 * (z * z)), 0.0)


class RbfPrimitive:
    """The motor primitive of one environment configuration."""

    def __init__(self, config: ArmBallsConfig | None = None) -> None:
        self.config = config or ArmBallsConfig()
        cfg = self.config
        self.n_params = cfg.n_params
        self.basis = rbf_basis(cfg.n_steps, cfg.n_rbf, cfg.rbf_sdev)  # (T, n_rbf)

    def check(self, params: np.ndarray) -> np.ndarray:
        """Validate parameters, shape (n_params,) or (N, n_params), finite, in [-1, 1].

        Returns:
            a float copy, shape (N, n_params) (N = 1 for a single vector).
        """
        p = np.array(params, dtype=float)
        if p.ndim == 1:
            p = p[None, :]
        if p.ndim != 2 or p.shape[1] != self.n_params:
            raise PrimitiveParameterError(
                f"motor parameters have shape {np.shape(params)}, expected ({self.n_params},) "
                f"or (N, {self.n_params})"
            )
        if not np.all(np.isfinite(p)):
            raise PrimitiveParameterError("motor parameters contain NaN or infinity")
        worst = float(np.max(np.abs(p))) if p.size else 0.0
        if worst > 1.0 + 1e-9:
            raise PrimitiveParameterError(
                f"motor parameters must lie in [-1, 1]; got a value of magnitude {worst:.3g}"
            )
        return p

    def commands(self, params: np.ndarray) -> np.ndarray:
        """Joint commands of one or many episodes.

        Args:
            params: shape (n_params,) or (N, n_params), in [-1, 1].

        Returns:
            shape (T, n_joints) for one vector, (N, T, n_joints) for many; in [-1, 1].
        """
        single = np.ndim(params) == 1
        p = self.check(params).reshape(-1, self.config.n_joints, self.config.n_rbf)
        # the bumps summed in a fixed order, not by BLAS (the same bits on every machine)
        out = np.clip(fixed_order.matmul(self.basis, p.transpose(0, 2, 1)), -1.0, 1.0)
        return out[0] if single else out
