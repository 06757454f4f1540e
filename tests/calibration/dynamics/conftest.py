"""Shared pieces of the servo-fit tests: a twin with known non-nominal servos, and short
recordings on it (two joints and the held-out segment: seconds, not minutes)."""

from __future__ import annotations

import numpy as np
import pytest

from calibration.dynamics import excitation
from calibration.dynamics.recording import Recording, record
from sim.arm import SimArm
from sim.servo_model import NOMINAL, ServoModel
from sim.twin import Twin

# Servos far from nominal on the two joints the short recording excites (m2, m3): kp x1.6 and
# x0.7, damping x0.65 and x1.4, armature x1.8 and x0.6, friction loss 8 and 3 mN.m, and a
# 12 ms command delay (the twin applies it at its next 5 ms physics step: 15 ms in effect).
TRUTH = NOMINAL.replace(
    kp=(3.5, 5.6, 2.45, 3.5, 3.5, 3.5),
    damping=(0.1, 0.065, 0.14, 0.1, 0.1, 0.1),
    armature=(0.0005, 0.0009, 0.0003, 0.0005, 0.0005, 0.0005),
    frictionloss=(0.001, 0.008, 0.003, 0.001, 0.001, 0.001),
    delay_s=0.012,
)
EFFECTIVE_DELAY_S = 0.015
JOINTS = [1, 2]  # m2, m3


class TwinClock:
    """Time is the twin's (as explore.rigs.clock.TwinClock)."""

    def __init__(self, twin: Twin) -> None:
        self.twin = twin

    def now(self) -> float:
        return self.twin.time

    def advance(self, seconds: float) -> None:
        self.twin.step(seconds)


def record_on(
    servos: ServoModel, joints=JOINTS, arm_hook=None, clock_hook=None, watchdog=None
) -> Recording:
    """A recording of ``joints`` (and the held-out segment) on a twin with ``servos``."""
    twin = Twin(servos=servos)
    arm = SimArm(twin, watchdog=watchdog)
    clock = TwinClock(twin)
    with arm:
        arm.set_torque(True)
        if arm_hook:
            arm_hook(twin)
        if clock_hook:
            clock = clock_hook(clock)
        return record(
            arm, clock, excitation.plan(arm.spec, joints, repeats=1), reads_per_tick=5,
            meta={"rig_id": "t", "backend": "twin"},
        )  # fmt: skip


@pytest.fixture(scope="session")
def truth_recording() -> Recording:
    return record_on(TRUTH)


@pytest.fixture(scope="session")
def truth_fit(truth_recording):
    from calibration.dynamics.fit import fit

    return fit(truth_recording)


def ratio(a, b) -> np.ndarray:
    return np.asarray(a, float) / np.asarray(b, float)
