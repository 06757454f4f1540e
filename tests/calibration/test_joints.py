"""Joint calibration through the ``robot.Arm`` interface: a scripted "user" moves the twin's
limp joints; servos that report offset and reversed angles are recovered; bad measurements are
refused with a one-line reason naming the joint."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from calibration import store
from calibration.joints import JointCalibration, Step, calibrate_joints, steps_for
from calibration.store import CalibrationError
from robot.arm import Arm, JointState
from robot.spec import ergo_jr_spec
from sim.arm import SimArm
from sim.twin import Twin

# How the "servos" of the test arm are mounted: raw = direction * joint + offset (rad).
OFFSETS = np.radians([10.0, -25.0, 170.0, 0.0, 5.0, -3.0])  # m3's limits wrap past 180 deg
DIRECTIONS = np.array([1.0, -1.0, 1.0, -1.0, 1.0, 1.0])


class MountedArm(Arm):
    """A SimArm seen through servos mounted with offsets and reversed directions, as a real
    rig reports raw servo angles in (-pi, pi]."""

    def __init__(self, inner: SimArm) -> None:
        super().__init__(inner.spec)
        self.inner = inner

    def _connect(self) -> None:
        self.inner.connect()

    def _disconnect(self) -> None:
        self.inner.disconnect()

    def _read(self) -> JointState:
        s = self.inner._read()
        raw = DIRECTIONS * s.positions + OFFSETS
        raw = np.pi - np.mod(np.pi - raw, 2 * np.pi)
        return JointState.from_positions(raw, s.timestamp, temperatures=s.temperatures)

    def _send(self, positions: np.ndarray) -> None:
        pass  # calibration never commands

    def _set_torque(self, enabled: bool) -> None:
        self.inner._set_torque(enabled)


def user_moves_twin(twin: Twin, margin: float = math.radians(3.0)):
    """The scripted user: puts the joint at 0 or just inside its spec limit, and holds it."""
    spec = ergo_jr_spec()

    def prompt(step: Step) -> None:
        j = spec.joints[step.index]
        target = {"zero": 0.0, "lower": j.lower + margin, "upper": j.upper - margin}[step.target]
        twin.data.qpos[twin._qpos_idx[step.index]] = target
        twin.data.qvel[:] = 0.0
        mujoco.mj_forward(twin.model, twin.data)

    return prompt


@pytest.fixture
def twin():
    t = Twin(render_size=(64, 64))
    yield t
    t.close()


def test_recovers_offsets_directions_ranges(twin, tmp_path):
    spec = ergo_jr_spec()
    with MountedArm(SimArm(twin)) as arm:
        result = calibrate_joints(arm, user_moves_twin(twin))
        assert not arm.torque_enabled and not twin.torque_enabled()
    np.testing.assert_allclose(
        np.pi - np.mod(np.pi - result.offsets, 2 * np.pi),
        np.pi - np.mod(np.pi - OFFSETS, 2 * np.pi),
        atol=1e-6,
    )
    np.testing.assert_array_equal(result.directions, DIRECTIONS)
    margin = math.radians(3.0)
    np.testing.assert_allclose(result.lower, spec.lower + margin, atol=1e-6)
    np.testing.assert_allclose(result.upper, spec.upper - margin, atol=1e-6)
    # The mapping inverts the mounting.
    q = np.radians([30.0, -40.0, 80.0, -100.0, 20.0, 10.0])
    raw = DIRECTIONS * q + OFFSETS
    np.testing.assert_allclose(result.to_joint(raw), q, atol=1e-9)
    narrowed = result.apply_to(spec)
    assert np.all(narrowed.lower >= spec.lower) and np.all(narrowed.upper <= spec.upper)
    # Saved and read back through the store.
    store.save("joints", "twin", result.to_dict(), tmp_path)
    back = JointCalibration.from_dict(store.load("joints", "twin", tmp_path))
    np.testing.assert_allclose(back.offsets, result.offsets)
    np.testing.assert_array_equal(back.directions, result.directions)


def test_some_joints_only(twin):
    with MountedArm(SimArm(twin)) as arm:
        result = calibrate_joints(arm, user_moves_twin(twin), joints=["m2"])
    assert result.directions[1] == -1 and result.offsets[1] == pytest.approx(OFFSETS[1])
    assert result.offsets[0] == 0.0 and result.directions[0] == 1.0  # untouched
    assert [s.target for s in steps_for(ergo_jr_spec(), ["m2"])] == ["zero", "lower", "upper"]
    with pytest.raises(CalibrationError, match="unknown joint 'm9'"):
        steps_for(ergo_jr_spec(), ["m9"])


def test_refusals(twin):
    def lazy_user(step: Step) -> None:  # never moves anything
        pass

    with MountedArm(SimArm(twin)) as arm, pytest.raises(CalibrationError) as err:
        calibrate_joints(arm, lazy_user, joints=["m1"])
    assert "joint m1" in str(err.value) and "was it moved" in str(err.value)

    # The user took the wrong zero mark: the range then passes the spec's limit.
    inner = user_moves_twin(twin)

    def wrong_zero(step: Step) -> None:
        inner(step)
        if step.target == "zero":
            twin.data.qpos[twin._qpos_idx[step.index]] = math.radians(-60.0)
            mujoco.mj_forward(twin.model, twin.data)

    with MountedArm(SimArm(twin)) as arm, pytest.raises(CalibrationError) as err:
        calibrate_joints(arm, wrong_zero, joints=["m3"])
    msg = str(err.value)
    assert msg.startswith("joint m3: measured range") and "wrong zero mark" in msg
    assert "\n" not in msg
