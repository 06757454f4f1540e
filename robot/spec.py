"""Joint specifications of the arm and the safety clamp every command goes through.

Units: radians for positions, radians per tick for the step bound.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np


@dataclass(frozen=True)
class JointSpec:
    """One revolute joint.

    Attributes:
        name: joint name (``m1`` .. ``m6`` on the Ergo Jr).
        servo_id: bus id of its servo (Dynamixel id or CANopen node id).
        lower, upper: position limits in radians.
        rest: rest position in radians (inside the limits).
    """

    name: str
    servo_id: int
    lower: float
    upper: float
    rest: float = 0.0

    def __post_init__(self) -> None:
        if not self.lower < self.upper:
            raise ValueError(f"joint {self.name}: lower limit {self.lower} >= upper {self.upper}")
        if not self.lower <= self.rest <= self.upper:
            raise ValueError(f"joint {self.name}: rest {self.rest} outside its limits")


@dataclass(frozen=True)
class ArmSpec:
    """The arm's joints plus the maximum step a single command may move any joint.

    Attributes:
        joints: the joints in command order.
        max_step: largest change of any joint between two consecutive commands, rad.
    """

    joints: tuple[JointSpec, ...]
    max_step: float = field(default=0.15)

    @property
    def names(self) -> list[str]:
        return [j.name for j in self.joints]

    @property
    def ids(self) -> list[int]:
        return [j.servo_id for j in self.joints]

    # The arrays below are computed once (the spec is frozen) and read-only: ``clamp`` runs on
    # every command, 80 times an episode, and building them each time was a third of its cost.
    @cached_property
    def lower(self) -> np.ndarray:
        """Lower limits, shape (n,), rad (read-only)."""
        return _read_only([j.lower for j in self.joints])

    @cached_property
    def upper(self) -> np.ndarray:
        """Upper limits, shape (n,), rad (read-only)."""
        return _read_only([j.upper for j in self.joints])

    @cached_property
    def rest(self) -> np.ndarray:
        """Rest pose, shape (n,), rad (read-only)."""
        return _read_only([j.rest for j in self.joints])

    @property
    def n(self) -> int:
        return len(self.joints)

    def with_limits(self, lower: np.ndarray, upper: np.ndarray) -> ArmSpec:
        """A copy with narrowed limits (e.g. from a joint calibration), never widened."""
        joints = tuple(
            replace(
                j,
                lower=max(j.lower, float(lo)),
                upper=min(j.upper, float(hi)),
                rest=min(max(j.rest, float(lo)), float(hi)),
            )
            for j, lo, hi in zip(self.joints, lower, upper, strict=True)
        )
        return replace(self, joints=joints)

    def clamp(self, target: np.ndarray, previous: np.ndarray | None) -> np.ndarray:
        """Clamp a command to the limits and to ``max_step`` from the previous command.

        Args:
            target: wanted positions, shape (n,), rad. NaN is refused.
            previous: last positions sent (or measured), shape (n,), rad; None skips the step
                bound (only for the very first command after connect, which callers should
                avoid by seeding it with the measured positions).

        Returns:
            positions that are safe to send, shape (n,), rad: within ``max_step`` of
            ``previous``, and inside the limits unless ``previous`` itself is outside them
            (then one ``max_step`` closer to them).
        """
        target = np.asarray(target, dtype=float).reshape(-1)
        if target.shape != (self.n,):
            raise ValueError(f"command has shape {target.shape}, expected ({self.n},)")
        # Plain floats: for six joints a Python loop costs half of the numpy expression
        # (7 against 13 us a command, 80 commands an episode) and gives the same bits
        # (min/max, then prev +- max_step, as np.clip / np.where / np.sign did).
        wanted = target.tolist()
        if not all(map(math.isfinite, wanted)):
            raise ValueError(f"command has non-finite values: {target}")
        inside = [min(max(x, lo), hi) for x, lo, hi in zip(wanted, *self._limit_lists, strict=True)]
        if previous is None:
            return np.array(inside)
        prev = np.asarray(previous, dtype=float).reshape(self.n)
        before = prev.tolist()
        if not all(map(math.isfinite, before)):
            raise ValueError(f"previous command has non-finite values: {prev}")
        # Towards the target brought inside the limits, at most max_step: from inside the
        # limits this stays inside; from outside (an arm moved by hand past narrowed limits)
        # it walks back in at max_step per tick instead of jumping to the limit. The target
        # itself when within reach (exactly: no rounding outside the limits).
        step = self.max_step
        return np.array(
            [
                x if abs(x - p) <= step else (p + step if x > p else p - step)
                for x, p in zip(inside, before, strict=True)
            ]
        )

    @cached_property
    def _limit_lists(self) -> tuple[list[float], list[float]]:
        """(lower, upper) limits as lists of floats, rad (for ``clamp``)."""
        return [j.lower for j in self.joints], [j.upper for j in self.joints]


def joint_mounting(
    n: int, directions: object = None, offsets: object = None
) -> tuple[np.ndarray, np.ndarray]:
    """How ``n`` servos sit on their joints: ``directions``, shape (n,), +1 where the servo's
    angle grows with the joint's and -1 where against it, and ``offsets``, shape (n,), rad,
    the joint angle at servo angle 0 (None: all +1, all 0). Returns float arrays; a one-line
    ``ValueError`` naming the wrong argument."""
    d = np.ones(n) if directions is None else np.asarray(directions, float)
    o = np.zeros(n) if offsets is None else np.asarray(offsets, float)
    if d.shape != (n,) or not np.all(np.isin(d, (-1.0, 1.0))):
        raise ValueError(f"directions must be {n} values of +1 or -1, got {directions}")
    if o.shape != (n,) or not np.all(np.isfinite(o)):
        raise ValueError(f"offsets must be {n} finite angles in rad, got {offsets}")
    return d, o


def _read_only(values: list[float]) -> np.ndarray:
    a = np.array(values, dtype=float)
    a.flags.writeable = False
    return a


def _deg(lo: float, hi: float) -> tuple[float, float]:
    return math.radians(lo), math.radians(hi)


# Poppy Ergo Jr motor names (servo ids 1..6 in this order) and angle limits in degrees: the
# Poppy project's Ergo Jr configuration (docs/facts.md).
ERGO_JR_LIMITS_DEG: dict[str, tuple[float, float]] = {
    "m1": (-150.0, 150.0),
    "m2": (-90.0, 125.0),
    "m3": (-90.0, 90.0),
    "m4": (-150.0, 150.0),
    "m5": (-90.0, 90.0),
    "m6": (-110.0, 90.0),
}

ERGO_JR_JOINTS: tuple[str, ...] = tuple(ERGO_JR_LIMITS_DEG)  # m1..m6, command order

# The rate the arm is commanded at, Hz: the DMP's 40 points at dt = 1/40 s, as on the paper's
# rig (the original implementation; docs/facts.md). Episodes, the DMP's time scale and the
# recorder's time line all run at it; the step bound below is per tick of it.
CONTROL_RATE_HZ = 40.0

# Horizontal reach of the tool tip from the axis of m1, m: 0.054 + 0.0298 + 0.048 + 0.054 +
# 0.07 = 0.256 m from the shoulder (the Ergo Jr kinematics, sim/models/README.md), rounded up.
# The end-effector grid and MGE-EFR's hand module are scaled by it.
ERGO_JR_REACH_M = 0.30

# Maximum step per command: 0.15 rad at the 40 Hz control rate is 6 rad/s, about half the
# XL-320's no-load speed (114 rpm = 11.9 rad/s at 7.4 V, ROBOTIS datasheet). Guess, on the
# safe side.
ERGO_JR_MAX_STEP = 0.15


def ergo_jr_spec(max_step: float = ERGO_JR_MAX_STEP) -> ArmSpec:
    """The Poppy Ergo Jr: joints ``ERGO_JR_JOINTS`` (m1..m6), servo ids 1..6, rest pose all
    zeros."""
    joints = tuple(
        JointSpec(name, i + 1, *_deg(*lim), rest=0.0)
        for i, (name, lim) in enumerate(ERGO_JR_LIMITS_DEG.items())
    )
    return ArmSpec(joints=joints, max_step=max_step)
