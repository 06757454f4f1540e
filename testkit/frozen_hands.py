"""A person's hands on a twin that is not stepped: the joints put where ``ergo calibrate
joints`` asks and held there, for the tests of zero marks anywhere on a servo's turn (the
twin has no real-time loop and no fake clock: nothing moves but what the hands move, so a
calibration reads exactly what they set, on any bus emulator).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence

import mujoco
import numpy as np

from calibration.joints import JointCalibration, Step, calibrate_joints
from robot.arm import Arm
from robot.spec import ArmSpec
from sim.twin import Twin

# How far inside each of the spec's limits the hands stop a joint, rad (one does not lean on a
# stop; the guide's owner stops 0.5 deg short, testkit.standin_owner).
MARGIN_RAD = math.radians(3.0)


def pose(twin: Twin, q: Sequence[float] | Mapping[int, float]) -> None:
    """Put the twin's joints at ``q`` (rad: all six, or {joint index: angle}) at rest."""
    items = q.items() if isinstance(q, Mapping) else enumerate(q)
    with twin.lock:
        for i, angle in items:
            twin.data.qpos[twin._qpos_idx[i]] = angle
        twin.data.qvel[:] = 0.0
        mujoco.mj_forward(twin.model, twin.data)


def hands(twin: Twin, spec: ArmSpec) -> Callable[[Step], None]:
    """The ``prompt`` of ``calibrate_joints``: each joint a step names put at 0 or
    ``MARGIN_RAD`` inside its spec limit."""

    def prompt(step: Step) -> None:
        where = {}
        for i in step.indices:
            j = spec.joints[i]
            where[i] = {"zero": 0.0, "lower": j.lower + MARGIN_RAD, "upper": j.upper - MARGIN_RAD}[
                step.target
            ]
        pose(twin, where)

    return prompt


def calibrate(raw_arm: Arm, twin: Twin) -> JointCalibration:
    """``calibrate_joints`` on an arm that reports raw servo angles, the hands moving the
    twin; the arm is connected and disconnected here."""
    pose(twin, np.zeros(raw_arm.spec.n))
    with raw_arm:
        return calibrate_joints(raw_arm, hands(twin, raw_arm.spec))


def first_torque_on(arm: Arm, twin: Twin, q0: Sequence[float]) -> np.ndarray:
    """A calibrated arm with the twin's joints at ``q0``: connect, torque on, read, one
    command holding where it read, read again, torque off. Returns the joint angles read at
    torque on, shape (n,), rad (the bus emulator's goals are the caller's to check)."""
    pose(twin, q0)
    with arm:
        arm.set_torque(True)
        q = arm.read().positions
        arm.command(q)
        arm.read()
        return q
