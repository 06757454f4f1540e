"""Joint offsets, directions and ranges, measured by hand through the ``robot.Arm`` interface.

With torque off, the user moves each joint in turn to its zero mark, to its lower (negative)
limit and to its upper (positive) limit; the arm is only *read* (``Arm.read().positions``).
The arm must report raw servo angles (directions +1, offsets 0) so that the result can be given
to the backend, e.g. ``DynamixelArm(directions=..., offsets=...)``, whose convention is the
one used here::

    servo_angle = direction * joint_angle + offset       joint_angle = direction * (servo - offset)

Differences of angles are wrapped to (-pi, pi], so a servo whose reading wraps between its
zero and a limit (lerobot issue #3586) still calibrates correctly.

The procedure is a plain function driven by a ``prompt(step)`` callback: interactive on the
command line (``input()``), scripted in tests (the callback moves the twin's joint).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from calibration.store import CalibrationError
from robot.arm import Arm
from robot.spec import ArmSpec

Target = Literal["zero", "lower", "upper"]
LIMIT_TOLERANCE_RAD = math.radians(5.0)  # measured limits may pass the spec's by this (guess)
MIN_RANGE_RAD = math.radians(20.0)  # a smaller measured range means the joint was not moved
MAX_JITTER_RAD = math.radians(2.0)  # readings of one step must agree within this (held still)
SAMPLES = 5  # readings averaged per step


@dataclass(frozen=True)
class Step:
    """One instruction to the user.

    Attributes:
        joint: joint name; index: its position in the spec.
        target: where to move it: its zero mark, or its lower or upper limit.
        message: the instruction in words.
    """

    joint: str
    index: int
    target: Target
    message: str


@dataclass(frozen=True)
class JointCalibration:
    """Per joint (arrays of shape (n,)): ``offsets`` servo angle at joint zero (rad),
    ``directions`` +1 or -1, ``lower``/``upper`` joint limits (rad, joint frame, inside the
    spec's limits)."""

    names: tuple[str, ...]
    offsets: np.ndarray
    directions: np.ndarray
    lower: np.ndarray
    upper: np.ndarray

    def to_joint(self, servo: np.ndarray) -> np.ndarray:
        """Raw servo angles (n,) rad -> joint angles (n,) rad."""
        return self.directions * _wrap(np.asarray(servo, float) - self.offsets)

    def to_servo(self, joint: np.ndarray) -> np.ndarray:
        """Joint angles (n,) rad -> raw servo angles (n,) rad."""
        return self.directions * np.asarray(joint, float) + self.offsets

    def apply_to(self, spec: ArmSpec) -> ArmSpec:
        """The spec narrowed to the measured limits (never widened)."""
        return spec.with_limits(self.lower, self.upper)

    def to_dict(self) -> dict[str, Any]:
        return {
            "names": list(self.names),
            "offsets": self.offsets.tolist(),
            "directions": [int(d) for d in self.directions],
            "lower": self.lower.tolist(),
            "upper": self.upper.tolist(),
            "units": "rad",
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> JointCalibration:
        return cls(
            tuple(d["names"]),
            np.asarray(d["offsets"], float),
            np.asarray(d["directions"], float),
            np.asarray(d["lower"], float),
            np.asarray(d["upper"], float),
        )


def _wrap(angle: np.ndarray | float) -> np.ndarray:
    """Angles to (-pi, pi]."""
    a = np.asarray(angle, float)
    return np.pi - np.mod(np.pi - a, 2 * np.pi)


def steps_for(spec: ArmSpec, joints: Sequence[str] | None = None) -> list[Step]:
    """The instructions, in order, for the given joints (default: all)."""
    names = list(joints) if joints is not None else spec.names
    out = []
    for name in names:
        if name not in spec.names:
            raise CalibrationError(f"unknown joint {name!r}; the arm has {', '.join(spec.names)}")
        i = spec.names.index(name)
        j = spec.joints[i]
        lo, hi = math.degrees(j.lower), math.degrees(j.upper)
        out += [
            Step(
                name, i, "zero", f"Move {name} to its zero mark (the rest pose), then press Enter"
            ),
            Step(
                name,
                i,
                "lower",
                f"Move {name} to its lower limit (negative way, about {lo:.0f} deg), then Enter",
            ),
            Step(
                name,
                i,
                "upper",
                f"Move {name} to its upper limit (positive way, about {hi:+.0f} deg), then Enter",
            ),
        ]
    return out


def _read_still(arm: Arm, index: int, samples: int) -> float:
    """Circular mean of ``samples`` readings of one joint; refuses a joint that moved."""
    vals = np.array([arm.read().positions[index] for _ in range(samples)], float)
    ref = vals[0]
    d = _wrap(vals - ref)
    if np.ptp(d) > MAX_JITTER_RAD:
        raise CalibrationError(
            f"joint {arm.spec.names[index]} moved by {math.degrees(np.ptp(d)):.1f} deg while "
            "being read: hold it still and repeat"
        )
    return float(_wrap(ref + d.mean()))


def calibrate_joints(
    arm: Arm,
    prompt: Callable[[Step], None],
    joints: Sequence[str] | None = None,
    samples: int = SAMPLES,
    tolerance_rad: float = LIMIT_TOLERANCE_RAD,
) -> JointCalibration:
    """Run the procedure on a connected arm; returns the calibration (not yet saved).

    Args:
        arm: a connected ``robot.Arm`` reporting raw servo angles. Torque is turned off first
            and left off.
        prompt: called with each ``Step``; returns when the joint is in place.
        joints: joint names to calibrate (default all); the others keep offset 0, direction
            +1 and the spec's limits.
        samples: readings averaged per step.
        tolerance_rad: how far a measured limit may pass the spec's before it is refused.

    Raises:
        CalibrationError: one line naming the joint and what is wrong.
    """
    spec = arm.spec
    arm.set_torque(False)
    n = spec.n
    offsets = np.zeros(n)
    directions = np.ones(n)
    lower = spec.lower.copy()
    upper = spec.upper.copy()
    readings: dict[tuple[int, str], float] = {}
    for step in steps_for(spec, joints):
        prompt(step)
        readings[(step.index, step.target)] = _read_still(arm, step.index, samples)
    done = sorted({i for i, _ in readings})
    for i in done:
        name = spec.names[i]
        zero = readings[(i, "zero")]
        d_lo = float(_wrap(readings[(i, "lower")] - zero))
        d_hi = float(_wrap(readings[(i, "upper")] - zero))
        if abs(d_hi - d_lo) < MIN_RANGE_RAD:
            raise CalibrationError(
                f"joint {name}: its limits are only {math.degrees(abs(d_hi - d_lo)):.0f} deg "
                f"apart (need >= {math.degrees(MIN_RANGE_RAD):.0f}): was it moved?"
            )
        direction = 1.0 if d_hi > d_lo else -1.0
        lo, hi = direction * d_lo, direction * d_hi
        if not lo <= 0.0 <= hi:
            raise CalibrationError(
                f"joint {name}: the zero mark is not between the limits "
                f"({math.degrees(lo):.0f}..{math.degrees(hi):.0f} deg)"
            )
        j = spec.joints[i]
        if lo < j.lower - tolerance_rad or hi > j.upper + tolerance_rad:
            raise CalibrationError(
                f"joint {name}: measured range {math.degrees(lo):.0f}..{math.degrees(hi):.0f} "
                f"deg exceeds the spec's {math.degrees(j.lower):.0f}..{math.degrees(j.upper):.0f}"
                f" deg by more than {math.degrees(tolerance_rad):.0f}: wrong zero mark?"
            )
        offsets[i] = zero
        directions[i] = direction
        lower[i] = max(lo, j.lower)
        upper[i] = min(hi, j.upper)
    return JointCalibration(tuple(spec.names), offsets, directions, lower, upper)


def interactive_prompt(step: Step) -> None:
    """Ask on the terminal and wait for Enter."""
    input(f"[{step.joint}] {step.message}: ")
