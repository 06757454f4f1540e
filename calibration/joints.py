"""Joint offsets, directions and ranges, measured by hand through the ``robot.Arm`` interface.

With torque off, the user puts the arm in its zero pose (every joint at its zero mark, one
prompt), then moves each joint in turn to its lower (negative) and its upper (positive) limit;
the arm is only *read* (``Arm.read().positions``). Each joint is checked as soon as its two
limits are read: a joint that was not moved, or whose zero mark is not between its limits, is
reported at once (``notify``) with the fix, and that joint is asked again (up to
``MAX_ATTEMPTS`` times). The arm must report raw servo angles (directions +1, offsets 0) so
that the result can be given to the backend, e.g. ``DynamixelArm(directions=...,
offsets=...)``, whose convention is the one used here::

    servo_angle = direction * joint_angle + offset       joint_angle = direction * (servo - offset)

Whole turns follow ``robot.angles``, the rule every arm and emulator shares: differences of
angles are wrapped to (-pi, pi], so a servo whose reading wraps between its zero and a limit
(lerobot issue #3586) still calibrates correctly, and each offset is saved in the turn the arm
reports the zero mark in (its readings' circular mean, not wrapped again). Any turn of an
offset is the same offset: an arm reads joint angles modulo whole turns and moves the offset
to the turn its servo or drive reads before it reckons goals and limits in the drive's own
units (``robot.angles.anchor``), so a zero mark past pi or beyond one turn calibrates and
drives like any other.

The procedure is a plain function driven by a ``prompt(step)`` callback: interactive on the
command line (``input()``), scripted in tests (the callback moves the twin's joint). Nothing is
written here: the caller saves the result once the whole procedure has succeeded, so an
interrupted calibration (stdin closed, Ctrl-C) leaves the previous file as it was.

``load_joints_file`` reads a saved calibration for an arm, refusing (one line naming the file)
one made for other joints or whose ranges miss the arm's.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np

from calibration.store import CalibrationError, load_file
from robot.angles import joint_angle, mean_angle, spread
from robot.arm import Arm
from robot.spec import ArmSpec

Target = Literal["zero", "lower", "upper"]
LIMIT_TOLERANCE_RAD = math.radians(5.0)  # measured limits may pass the spec's by this (guess)
MIN_RANGE_RAD = math.radians(20.0)  # a smaller measured range means the joint was not moved
MAX_JITTER_RAD = math.radians(2.0)  # readings of one step must agree within this (held still)
SAMPLES = 5  # readings averaged per step
# How often one joint (or one step held unsteadily) is asked again before the procedure gives
# up: a person fixes a slip on the second try; a script that never moves the joint must end.
MAX_ATTEMPTS = 3


@dataclass(frozen=True)
class Step:
    """One instruction to the user.

    Attributes:
        target: ``"zero"``: every joint of ``indices`` at its zero mark (the zero pose, all at
            once); ``"lower"`` / ``"upper"``: the one joint of ``indices`` at that limit.
        indices: the joints to move, as positions in the spec.
        names: their names.
        message: the instruction in words.
        attempt: 1 the first time; 2, 3... when the joint is asked again after a problem
            (which ``notify`` was told just before).
    """

    target: Target
    indices: tuple[int, ...]
    names: tuple[str, ...]
    message: str
    attempt: int = 1

    @property
    def index(self) -> int:
        """The joint of a limit step (the first of a zero step's)."""
        return self.indices[0]

    @property
    def joint(self) -> str:
        """Which joints, in words: ``m1``, or ``m1, m2, ...`` for a zero pose."""
        return ", ".join(self.names)


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
        """Raw servo angles (n,) rad -> joint angles (n,) rad, in (-pi, pi]."""
        return joint_angle(servo, self.offsets, self.directions)

    def to_servo(self, joint: np.ndarray) -> np.ndarray:
        """Joint angles (n,) rad -> raw servo angles (n,) rad, in each offset's turn."""
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


def _joint_indices(spec: ArmSpec, joints: Sequence[str] | None) -> list[int]:
    names = list(joints) if joints is not None else spec.names
    for name in names:
        if name not in spec.names:
            raise CalibrationError(f"unknown joint {name!r}; the arm has {', '.join(spec.names)}")
    return [spec.names.index(name) for name in names]


def zero_step(spec: ArmSpec, indices: Sequence[int], attempt: int = 1) -> Step:
    """The step that puts the joints of ``indices`` at their zero marks (the zero pose)."""
    names = tuple(spec.names[i] for i in indices)
    if len(names) == spec.n:
        what = "the arm in its zero pose (every joint at its zero mark, the rest pose)"
    elif len(names) == 1:
        what = f"{names[0]} at its zero mark"
    else:
        what = f"{', '.join(names)} at their zero marks"
    return Step("zero", tuple(indices), names, f"Put {what}, then press Enter", attempt)


def limit_step(spec: ArmSpec, index: int, target: Target, attempt: int = 1) -> Step:
    """The step that moves one joint to its lower or upper limit."""
    j = spec.joints[index]
    if target == "lower":
        words = f"lower limit (negative way, about {math.degrees(j.lower):.0f} deg)"
    else:
        words = f"upper limit (positive way, about {math.degrees(j.upper):+.0f} deg)"
    message = f"Move {j.name} to its {words}, then press Enter"
    return Step(target, (index,), (j.name,), message, attempt)


def steps_for(spec: ArmSpec, joints: Sequence[str] | None = None) -> list[Step]:
    """The instructions, in order, for the given joints (default: all) when nothing has to be
    asked again: the zero pose once, then each joint's lower and upper limits."""
    indices = _joint_indices(spec, joints)
    out = [zero_step(spec, indices)]
    for i in indices:
        out += [limit_step(spec, i, "lower"), limit_step(spec, i, "upper")]
    return out


def _read_still(arm: Arm, indices: Sequence[int], samples: int) -> np.ndarray | str:
    """Circular means of ``samples`` readings of the joints ``indices``, shape (len,), rad, in
    the turn the servos read (not wrapped: ``robot.angles.mean_angle``); or, when one of them
    moved while being read, what to tell the user."""
    idx = list(indices)
    vals = np.array([arm.read().positions[idx] for _ in range(samples)], float)  # (samples, k)
    moved = spread(vals, axis=0)
    if np.any(moved > MAX_JITTER_RAD):
        k = int(np.argmax(moved))
        return (
            f"joint {arm.spec.names[idx[k]]} moved by {math.degrees(moved[k]):.1f} deg while "
            "being read: hold it still, then press Enter"
        )
    return mean_angle(vals, axis=0)


def _check_joint(
    spec: ArmSpec, i: int, zero: float, lower: float, upper: float, tolerance_rad: float
) -> tuple[float, float, float] | tuple[str, bool]:
    """A joint's readings (raw servo angles, rad) -> (direction, lower, upper) in the joint
    frame, or (what is wrong with the fix, whether its zero mark must be taken again)."""
    name = spec.names[i]
    d_lo = float(joint_angle(lower, zero))
    d_hi = float(joint_angle(upper, zero))
    if abs(d_hi - d_lo) < MIN_RANGE_RAD:
        return (
            f"joint {name}: its limits are only {math.degrees(abs(d_hi - d_lo)):.0f} deg apart "
            f"(need >= {math.degrees(MIN_RANGE_RAD):.0f}): was it moved? Torque is off: move "
            f"{name} by hand all the way to each limit when asked",
            False,
        )
    direction = 1.0 if d_hi > d_lo else -1.0
    lo, hi = direction * d_lo, direction * d_hi
    if not lo <= 0.0 <= hi:
        return (
            f"joint {name}: the zero mark is not between the limits "
            f"({math.degrees(lo):.0f}..{math.degrees(hi):.0f} deg from it): put {name} at its "
            "zero mark again, then at its limits",
            True,
        )
    j = spec.joints[i]
    if lo < j.lower - tolerance_rad or hi > j.upper + tolerance_rad:
        return (
            f"joint {name}: measured range {math.degrees(lo):.0f}..{math.degrees(hi):.0f} "
            f"deg exceeds the spec's {math.degrees(j.lower):.0f}..{math.degrees(j.upper):.0f}"
            f" deg by more than {math.degrees(tolerance_rad):.0f}: wrong zero mark? Put {name} "
            "at its zero mark again, then at its limits",
            True,
        )
    return direction, lo, hi


def calibrate_joints(
    arm: Arm,
    prompt: Callable[[Step], None],
    joints: Sequence[str] | None = None,
    samples: int = SAMPLES,
    tolerance_rad: float = LIMIT_TOLERANCE_RAD,
    notify: Callable[[str], None] | None = None,
    max_attempts: int = MAX_ATTEMPTS,
) -> JointCalibration:
    """Run the procedure on a connected arm; returns the calibration (not yet saved).

    The zero pose is asked once for all the joints, then each joint's lower and upper limits.
    A joint is checked as soon as its limits are read; a problem (not moved, zero mark not
    between its limits, range past the spec's) is given to ``notify`` with its fix and the
    joint is asked again (its zero mark too when that is what looks wrong); a step during
    which a joint moved is asked again the same way.

    Args:
        arm: a connected ``robot.Arm`` reporting raw servo angles. Torque is turned off first
            and left off.
        prompt: called with each ``Step``; returns when the joints are in place (an
            ``EOFError`` or ``KeyboardInterrupt`` it raises ends the procedure, nothing saved).
        joints: joint names to calibrate (default all); the others keep offset 0, direction
            +1 and the spec's limits.
        samples: readings averaged per step.
        tolerance_rad: how far a measured limit may pass the spec's before it is refused.
        notify: told each problem, one line with its fix, before the step is asked again
            (default: not told).
        max_attempts: tries per joint (and per step) before giving up.

    Raises:
        CalibrationError: one line naming the joint and what is wrong, after
            ``max_attempts`` tries.
    """
    spec = arm.spec
    indices = _joint_indices(spec, joints)
    tell = notify or (lambda message: None)

    def ask(step: Step) -> np.ndarray:
        while True:
            prompt(step)
            got = _read_still(arm, step.indices, samples)
            if not isinstance(got, str):
                return got
            if step.attempt >= max_attempts:
                raise CalibrationError(f"{got.split(':')[0]} (tried {step.attempt} times)")
            tell(got)
            step = Step(step.target, step.indices, step.names, step.message, step.attempt + 1)

    arm.set_torque(False)
    n = spec.n
    offsets = np.zeros(n)
    directions = np.ones(n)
    lower = spec.lower.copy()
    upper = spec.upper.copy()
    zero = dict(zip(indices, ask(zero_step(spec, indices)), strict=True))
    for i in indices:
        attempt = 1
        while True:
            lo_raw = float(ask(limit_step(spec, i, "lower", attempt))[0])
            hi_raw = float(ask(limit_step(spec, i, "upper", attempt))[0])
            checked = _check_joint(spec, i, zero[i], lo_raw, hi_raw, tolerance_rad)
            if isinstance(checked[0], float):
                break
            problem, again_zero = checked
            if attempt >= max_attempts:
                raise CalibrationError(f"{problem} (tried {attempt} times)")
            tell(f"{problem}; asking {spec.names[i]} again")
            attempt += 1
            if again_zero:
                zero[i] = float(ask(zero_step(spec, [i], attempt))[0])
        direction, lo, hi = checked
        j = spec.joints[i]
        offsets[i] = zero[i]
        directions[i] = direction
        lower[i] = max(lo, j.lower)
        upper[i] = min(hi, j.upper)
    return JointCalibration(tuple(spec.names), offsets, directions, lower, upper)


def load_joints_file(path: str | Path, spec: ArmSpec) -> JointCalibration:
    """A saved joint calibration for the arm ``spec`` describes.

    Raises:
        CalibrationMissing: there is no file (not a bad one).
        CalibrationError: one line naming the file: damaged or of another version
            (``calibration.store.load_file``), made for other joints, or a joint whose range
            misses the spec's.
    """
    path = Path(path)
    data = load_file(path, "joints")
    if list(data["names"]) != spec.names:
        raise CalibrationError(
            f"{path}: calibrates joints {', '.join(data['names'])}, the arm has "
            f"{', '.join(spec.names)}: calibrate it again (ergo calibrate joints --rig-id "
            f"{path.parent.name} ...)"
        )
    cal = JointCalibration.from_dict(data)
    for j, lo, hi in zip(spec.joints, cal.lower, cal.upper, strict=True):
        if not max(lo, j.lower) < min(hi, j.upper):
            raise CalibrationError(
                f"{path}: joint {j.name}'s range {math.degrees(lo):.0f}.."
                f"{math.degrees(hi):.0f} deg lies outside the arm's "
                f"{math.degrees(j.lower):.0f}..{math.degrees(j.upper):.0f} deg: calibrate it "
                "again"
            )
    return cal


def interactive_prompt(step: Step) -> None:
    """Ask on the terminal and wait for Enter (``EOFError`` when stdin is closed)."""
    again = f" (try {step.attempt})" if step.attempt > 1 else ""
    input(f"[{step.joint}]{again} {step.message}: ")
