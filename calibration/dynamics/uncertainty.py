"""How sure the fit is: 95 % intervals of the fitted servo parameters that do not assume the
residuals independent, and which parameters the recording does not identify.

Why not the textbook interval (``mujoco.sysid.calculate_intervals``: the Jacobian at the
optimum and the residuals' variance, as if every reading were an independent draw): the
residuals are correlated over hundreds of milliseconds (an XL-320's rounding is the same
while a joint is held; a late reading and a late command move several readings together) and
carry what the model does not (the bus's timing). On the stand-ins those intervals excluded
the hidden value on most joints (docs/results_dynamics.md).

The method, a delete-a-block jackknife (Kuensch, Ann. Stat. 17, 1217 (1989)), linearised at the
optimum:

1. the fit's own residuals ``r`` (``calibration.dynamics.noise``) and their Jacobian
   ``J`` with respect to the fitted log-ratios and the delay, by central differences of
   rollouts (``linearise``);
2. each training segment cut into blocks of ``BLOCK_S`` seconds, long against the residuals'
   correlation (measured: under 0.2 at 0.4 s on the stand-ins); for each block ``k``, the
   Gauss-Newton step that deleting it makes, ``d_k = (H - J_k' J_k)^-1 J_k' r_k``
   (``H = J' J``);
3. the held-out segment's blocks join in, each with the step deleting it would make had it
   been fitted, ``(H + J_k' J_k)^-1 J_k' r_k``: a held-out motion the model fits worse than the
   training (a mismatch the training's own blocks share) widens the intervals;
4. the covariance ``(K - 1) / K * sum_k (d_k - mean)(d_k - mean)'``: what the estimate would
   move by had another stretch of the same arm been recorded. It holds the noise, its
   correlation and whatever makes one stretch of the recording disagree with another (the
   model's mismatch), and assumes neither the weights nor the noise's shape;
5. Student's t with the blocks that carry each parameter (``dof``: sum(d^2)^2 / sum(d^4),
   less one): a joint's parameters rest on the few blocks of its own segment;
6. the model's mismatch, an error every block of one recording shares and so no block shows
   (the bus's timing, the XL-320's rounding, CANopen's SYNC: the fit's estimate is off by it
   however long the recording), added in quadrature: ``sqrt(half^2 + (z m)^2)``, ``m`` the
   log error beyond the jackknife's own measured on development stand-ins per bus and
   parameter (``MISMATCH_SD``, ``with_mismatch``);
7. the interval on the log-ratio, turned back into values (not symmetric).

A parameter is *not identified* (``Identification``) when its jackknife interval (what the
recording says, before item 6) spans more than
``MAX_SPAN`` (a factor of 2.0 between its ends: the recording leaves it free); the reason
names the parameter it trades against when their correlation passes ``MAX_CORRELATION``
(only their combination is fitted). The fitted value still serves the twin (it reproduces
the arm as well as any other value along that direction); the report and ``dynamics.json``
say it is not a measurement.

Units: log-ratios (dimensionless), the delay in ``fit.DELAY_UNIT_S``; values in the servo
model's units.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import stats

# Blocks of the jackknife, s: four or more per 6.4 s segment, each longer than the residuals'
# correlation (under 0.2 at 0.4 s, measured on the stand-ins over both buses; guess beyond).
BLOCK_S = 1.6
# An interval wider than this factor between its ends says the recording does not pin the
# parameter (2.0: +-41 % around the estimate; guess: a twin off by that much is another servo).
MAX_SPAN = 2.0
# Two parameters this correlated are one direction the recording sees and one it does not.
MAX_CORRELATION = 0.95
# Central differences of the log-ratios and of the delay (in DELAY_UNIT_S units: 0.05 = 0.5 ms)
LOG_STEP = 0.02
DELAY_STEP = 0.05
ALPHA = 0.05  # 95 % intervals
# The model's mismatch (item 6 above), 1 sd of a fitted log-ratio, per bus and parameter: the
# error beyond what each value's own jackknife sd explains, over the joints the fit called
# identified (``m`` with mean(e^2 / (sd^2 + m^2)) = 1, e the log error fitted / hidden: the
# Paule-Mandel estimate of a random effect, J. Res. NBS 87, 377 (1982)), on development
# stand-ins 303-305 recorded with 3 repeats (12-18 joints each; measured with
# ``experiments/standin_dynamics.py --seeds 303 304 305 --repeats 3 --keep DIR
# --record-only``, ``--refit LABEL``, then ``--table LABEL --mismatch``). Measured on served
# stand-ins; for a physical arm a lower bound (guess: its servos hold more than the twin
# models). The twin in process: none (it is the model). Another bus: the larger of the two.
MISMATCH_SD: dict[str, dict[str, float]] = {
    "dynamixel": {"kp": 0.034, "damping": 0.018, "armature": 0.041, "frictionloss": 0.102},
    "canopen": {"kp": 0.020, "damping": 0.0045, "armature": 0.052, "frictionloss": 0.055},
}


@dataclass
class Linearisation:
    """The fit's weighted residuals and their Jacobian at the optimum.

    Attributes:
        names: the free parameters ("m2.kp", ..., "delay"), (P,).
        jac: (N, P); residual: (N,) (dimensionless: ``calibration.dynamics.noise``).
        block: (N,) int, the jackknife block of each residual.
        fitted: (N,) bool, the residuals the fit minimised (None: all); the others (the
            held-out segment's) join the jackknife as blocks the fit did not see.
    """

    names: list[str]
    jac: np.ndarray
    residual: np.ndarray
    block: np.ndarray
    fitted: np.ndarray | None = None


@dataclass
class Intervals:
    """95 % intervals on the free parameters' log-ratios (the delay: ``fit.DELAY_UNIT_S``).

    Attributes:
        names: (P,); half: (P,) half widths; cov: (P, P) the jackknife covariance;
        dof: (P,) the t distribution's degrees of freedom; blocks: how many blocks.
    """

    names: list[str]
    half: np.ndarray
    cov: np.ndarray
    dof: np.ndarray
    blocks: int

    def correlation(self) -> np.ndarray:
        sd = np.sqrt(np.maximum(np.diag(self.cov), 1e-300))
        return self.cov / np.outer(sd, sd)


def block_ids(times: np.ndarray, block_s: float | None = None) -> np.ndarray:
    """Blocks of about ``block_s`` s (default ``BLOCK_S``) along one segment's readings, (M,)
    s -> (M,) int: the segment cut into equal blocks, as many as fit best."""
    block_s = BLOCK_S if block_s is None else block_s
    t = np.asarray(times, float) - float(times[0])
    span = float(t[-1]) if len(t) else 0.0
    n = max(1, round(span / block_s))
    return np.minimum((t / max(span, 1e-9) * n).astype(int), n - 1)


def jackknife(lin: Linearisation, alpha: float = ALPHA) -> Intervals:
    """The delete-a-block jackknife's intervals (module docstring)."""
    jac, r = lin.jac, lin.residual
    p = jac.shape[1]
    fitted = np.ones(len(r), bool) if lin.fitted is None else np.asarray(lin.fitted, bool)
    hess = jac[fitted].T @ jac[fitted]
    ids = np.unique(lin.block)
    steps = np.empty((len(ids), p))
    for i, b in enumerate(ids):
        m = lin.block == b
        jk = jac[m]
        # a block the fit saw: the step deleting it makes; one it did not: the step deleting
        # it would make had it been fitted (its pull on the estimate, same sign)
        sign = -1.0 if fitted[m].all() else 1.0
        steps[i] = np.linalg.lstsq(hess + sign * jk.T @ jk, jk.T @ r[m], rcond=None)[0]
    k = len(ids)
    dev = steps - steps.mean(axis=0)
    cov = (k - 1) / k * dev.T @ dev
    # the blocks that carry each parameter (Satterthwaite): k for equal shares, 1 for one block
    sq = dev**2
    carried = np.square(sq.sum(axis=0)) / np.maximum(np.sum(sq**2, axis=0), 1e-300)
    dof = np.maximum(carried - 1.0, 1.0)
    half = stats.t.ppf(1 - alpha / 2, dof) * np.sqrt(np.maximum(np.diag(cov), 0.0))
    return Intervals(list(lin.names), half, cov, dof, k)


def mismatch_sd(backend: str | None, field: str) -> float:
    """``MISMATCH_SD`` of ``field`` on ``backend`` (a recording's ``meta["backend"]``): 0 on
    the twin in process, the larger of the buses' for a backend not measured."""
    if backend == "twin":
        return 0.0
    if backend in MISMATCH_SD:
        return MISMATCH_SD[backend][field]
    return max(sds[field] for sds in MISMATCH_SD.values())


def with_mismatch(half: float, backend: str | None, field: str, alpha: float = ALPHA) -> float:
    """A half width on a log-ratio (the jackknife's) widened by the model's mismatch on
    ``backend``: ``sqrt(half^2 + (z m)^2)``, z the normal's two-sided ``1 - alpha`` quantile."""
    z = float(stats.norm.ppf(1 - alpha / 2))
    return math.hypot(half, z * mismatch_sd(backend, field))


@dataclass
class Identification:
    """Whether a parameter is a measurement, and if not why (one line)."""

    identified: bool
    reason: str = ""


def identification(
    iv: Intervals, bounds: dict[str, tuple[float, float]]
) -> dict[str, Identification]:
    """Per free parameter (not the delay): identified, or the reason it is not.

    Args:
        iv: the intervals.
        bounds: per parameter name, the fit's bounds on its log-ratio (lo, hi).
    """
    corr = iv.correlation()
    out: dict[str, Identification] = {}
    for i, name in enumerate(iv.names):
        if name == "delay":
            continue
        span = math.exp(min(2 * iv.half[i], 700.0))
        others = [j for j in range(len(iv.names)) if j != i]
        j = max(others, key=lambda j: abs(corr[i, j])) if others else None
        if span <= MAX_SPAN:
            out[name] = Identification(True)
            continue
        lo, hi = bounds.get(name, (-math.inf, math.inf))
        why = f"the recording does not pin it: its 95 % interval spans a factor of {span:.3g}"
        if 2 * iv.half[i] >= hi - lo:
            why += ", wider than the fit's bounds"
        if j is not None and abs(corr[i, j]) > MAX_CORRELATION:
            why += f"; it trades against {iv.names[j]} (correlation {corr[i, j]:+.2f})"
        out[name] = Identification(False, why)
    return out


def linearise(
    residuals: Any,
    x: np.ndarray,
    names: list[str],
    blocks: np.ndarray,
    fitted: np.ndarray | None = None,
) -> Linearisation:
    """The Jacobian of ``residuals(x) -> (N,)`` at ``x`` (P,) by central differences
    (``LOG_STEP``, the delay ``DELAY_STEP``); ``blocks`` (N,) the jackknife's blocks, ``fitted``
    (N,) which residuals the fit minimised (``Linearisation``)."""
    r0 = np.asarray(residuals(x), float)
    cols = []
    for i, name in enumerate(names):
        h = DELAY_STEP if name == "delay" else LOG_STEP
        up, down = x.copy(), x.copy()
        up[i] += h
        down[i] -= h
        cols.append((np.asarray(residuals(up)) - np.asarray(residuals(down))) / (2 * h))
    return Linearisation(list(names), np.stack(cols, axis=1), r0, np.asarray(blocks), fitted)
