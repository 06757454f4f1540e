"""What a reading of a recording says about the arm's true angle at its time stamp, as the
fit's residual: the likelihood of a rounded, slightly mistimed reading.

A reading is the true angle, moved by a little noise, then rounded to the servo's raw unit
(``position_resolution``: an XL-320's 0.29 deg step, a drive's 0.0055 deg increment):

- the noise before rounding, per reading, sd ``sigma``: ``NOISE_FLOOR_RAD`` of everything else,
  and over a bus the time stamp's error ``TIMING_SD_S`` times the joint's speed (a reading
  taken a little before or after its stamp); on the twin in process (``backend`` "twin") the
  stamps are exact;
- the rounding: the reading ``k`` says the noisy angle lay within half a raw unit ``h`` of it:
  ``P(k | q) = Phi((k + h - q) / sigma) - Phi((k - h - q) / sigma)``.

The fit's residual of a reading is ``sign(q - k) sqrt(-2 log(P(k | q) / P(k | k)))``
(``residual``): flat inside the rounding's cell, the error over ``sigma`` outside it, the
plain ``(q - k) / sigma`` where ``h`` is small against ``sigma`` (a drive's increments, the
twin). Why not the plain difference over an XL-320: a joint held still reads the same rounded
value for seconds, its rounding error is one draw repeated hundreds of times, and the fit would
bend the joint's gain and friction to explain it (measured: the twin in process with the
hidden servos of a stand-in, readings rounded to an XL-320's step: kp off by up to 10 %, the
armature by up to -88 %, friction loss by up to +612 %, with exact goals; exact with exact
readings; docs/dynamics.md). A moving reading weighs less than a still one: its timing
error is larger (errors in the independent variable: the "effective variance" of Orear, Am. J.
Phys. 50, 912 (1982)). A residual beyond ``TAIL`` grows as its square root (Huber's loss): a
reading stamped long after it was taken, by a host that stalled, is not news of the servo.
None of this needs be exact: the intervals do not assume it
(``calibration/dynamics/uncertainty.py``).
"""

from __future__ import annotations

import numpy as np
from scipy.special import log_ndtr

# The time stamps' error over a bus, sd: 0.5-2.2 ms measured on the served stand-ins over both
# buses with the readings stamped when sampled (the time shift per reading that explains the
# hidden servos' error, experiments/standin_floor.py, docs/results_dynamics.md); 1.9-2.6 ms
# when they were stamped at the reply. Kept at the upper value; a guess for a physical link.
TIMING_SD_S = 0.0025
# Beyond this many sigmas a residual counts as a reading stamped long after it was taken (a
# host that stalled between the exchange and the stamp: readings 65-280 ms apart and 0.7-2.9 deg
# off on stand-in 300's m4 over the Dynamixel pty, measured), not as news of the servo: the
# cost grows linearly beyond it (Huber, Ann. Math. Statist. 35, 73 (1964)); 3 leaves 0.3 % of
# a Gaussian's readings past it.
TAIL = 3.0
# Every other error of a reading: 0.014-0.031 deg (0.25-0.55 mrad) is left of the hidden servos'
# error on CANopen once the timing is removed (docs/dynamics.md, measured): 0.5 mrad.
NOISE_FLOOR_RAD = 0.0005


def reading_speed(t: np.ndarray, q: np.ndarray) -> np.ndarray:
    """The joints' speed at each reading from the readings themselves, shape (M, n), rad/s:
    the slope over two readings either side (25 ms at 80 Hz: one raw unit of an XL-320 over
    that span is 0.2 rad/s), one side at the ends. Shapes: (M,) s, (M, n) rad."""
    t = np.asarray(t, float)
    q = np.asarray(q, float)
    if len(t) < 2:
        return np.zeros_like(q)
    k = min(2, len(t) - 1)
    lo = np.clip(np.arange(len(t)) - k, 0, len(t) - 1)
    hi = np.clip(np.arange(len(t)) + k, 0, len(t) - 1)
    dt = np.maximum(t[hi] - t[lo], 1e-6)
    return (q[hi] - q[lo]) / dt[:, None]


def reading_sigma(t: np.ndarray, q: np.ndarray, timed: bool = True) -> np.ndarray:
    """Each reading's noise before rounding, sd, shape (M, n), rad (module docstring).

    Args:
        t, q: the readings' times (M,), s, and joint angles (M, n), rad.
        timed: whether the stamps carry a bus's timing error (False on the twin in process).
    """
    if not timed:
        return np.full(np.shape(q), NOISE_FLOOR_RAD)
    return np.sqrt(NOISE_FLOOR_RAD**2 + np.square(reading_speed(t, q) * TIMING_SD_S))


def residual(err: np.ndarray, half_step: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    """The residual of readings whose true angle is ``err`` (rad) from them, rounded to half
    a raw unit ``half_step`` (rad, per joint, broadcast), with noise ``sigma`` (rad) before the
    rounding: ``sign(err) sqrt(-2 log(P(err) / P(0)))`` (module docstring); dimensionless."""
    err = np.asarray(err, float)
    d = np.abs(err)
    s = np.broadcast_to(np.asarray(sigma, float), d.shape)
    h = np.broadcast_to(np.asarray(half_step, float), d.shape)
    # a cell under a hundredth of sigma: the plain error over sigma (within 1e-4)
    h = np.maximum(h, 0.01 * s)
    a, b = (d - h) / s, (d + h) / s
    # log P(d) = log(Phi(-a) - Phi(-b)) and log P(0) = log(1 - 2 Phi(-h / s)), stably
    log_p = log_ndtr(-a) + np.log1p(-np.exp(log_ndtr(-b) - log_ndtr(-a)))
    log_p0 = np.log1p(-2.0 * np.exp(log_ndtr(-h / s)))
    r = np.sqrt(np.maximum(0.0, 2.0 * (log_p0 - log_p)))
    fine = np.asarray(half_step, float) < 0.01 * np.asarray(sigma, float)
    r = np.where(fine, d / s, r)
    # Huber's tails: beyond TAIL the cost grows linearly, as the square root of the residual
    r = np.where(r > TAIL, np.sqrt(np.maximum(2.0 * TAIL * r - TAIL**2, 0.0)), r)
    return np.sign(err) * r


def half_steps(meta: dict, n: int) -> np.ndarray:
    """Half a raw unit per joint from a recording's ``meta`` (zeros when it does not say), (n,),
    rad."""
    res = meta.get("position_resolution")
    return np.zeros(n) if not res else 0.5 * np.asarray(res, float).reshape(n)


def timed(meta: dict) -> bool:
    """Whether a recording's stamps carry a bus's timing error (all but the in-process twin)."""
    return meta.get("backend") != "twin"
