"""Joint calibration through the ``robot.Arm`` interface: a scripted "user" moves the twin's
limp joints; servos that report offset and reversed angles are recovered; the zero pose is
asked once, then each joint's limits; a joint not moved is reported at once with the fix and
asked again; bad measurements are refused with a one-line reason naming the joint; stdin
closed and Ctrl-C end ``ergo calibrate joints`` in one line with the previous file kept."""

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
        for i in step.indices:
            j = spec.joints[i]
            target = {"zero": 0.0, "lower": j.lower + margin, "upper": j.upper - margin}
            twin.data.qpos[twin._qpos_idx[i]] = target[step.target]
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
    # all joints: the zero pose once (all of them), then two limits each: 13 prompts, not 18
    steps = steps_for(ergo_jr_spec())
    assert len(steps) == 13 and steps[0].indices == (0, 1, 2, 3, 4, 5)
    assert [s.target for s in steps[1:3]] == ["lower", "upper"] and steps[1].joint == "m1"
    with pytest.raises(CalibrationError, match="unknown joint 'm9'"):
        steps_for(ergo_jr_spec(), ["m9"])


def test_a_joint_not_moved_is_reported_at_once_and_asked_again(twin):
    """The user forgets m2's limits the first time: told right after m2's upper limit (not at
    the end), with the fix, and m2 is asked again; the result is then right."""
    inner = user_moves_twin(twin)
    asked: list[tuple[str, str, int]] = []
    told: list[str] = []

    def forgetful(step: Step) -> None:
        asked.append((step.joint, step.target, step.attempt))
        if not (step.joint == "m2" and step.attempt == 1 and step.target != "zero"):
            inner(step)

    with MountedArm(SimArm(twin)) as arm:
        result = calibrate_joints(arm, forgetful, joints=["m1", "m2", "m3"], notify=told.append)
    assert len(told) == 1 and told[0].startswith("joint m2: its limits are only 0 deg apart")
    assert "was it moved? Torque is off: move m2 by hand" in told[0] and "\n" not in told[0]
    assert asked == [
        ("m1, m2, m3", "zero", 1), ("m1", "lower", 1), ("m1", "upper", 1),
        ("m2", "lower", 1), ("m2", "upper", 1),  # the problem is told here, at once
        ("m2", "lower", 2), ("m2", "upper", 2), ("m3", "lower", 1), ("m3", "upper", 1),
    ]  # fmt: skip
    assert result.directions[1] == DIRECTIONS[1]
    assert result.offsets[1] == pytest.approx(OFFSETS[1])


def test_refusals(twin):
    def lazy_user(step: Step) -> None:  # never moves anything
        pass

    told: list[str] = []
    with MountedArm(SimArm(twin)) as arm, pytest.raises(CalibrationError) as err:
        calibrate_joints(arm, lazy_user, joints=["m1"], notify=told.append)
    assert "joint m1" in str(err.value) and "was it moved" in str(err.value)
    assert "tried 3 times" in str(err.value) and len(told) == 2  # asked again twice

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


def test_a_wrong_zero_mark_is_taken_again_with_the_joint(twin):
    inner = user_moves_twin(twin)
    asked: list[tuple[str, str, int]] = []

    def wrong_zero_once(step: Step) -> None:
        asked.append((step.joint, step.target, step.attempt))
        inner(step)
        if step.target == "zero" and step.attempt == 1:
            twin.data.qpos[twin._qpos_idx[2]] = math.radians(-60.0)  # m3's mark mistaken
            mujoco.mj_forward(twin.model, twin.data)

    with MountedArm(SimArm(twin)) as arm:
        result = calibrate_joints(arm, wrong_zero_once, joints=["m3"])
    assert asked == [
        ("m3", "zero", 1), ("m3", "lower", 1), ("m3", "upper", 1),
        ("m3", "zero", 2), ("m3", "lower", 2), ("m3", "upper", 2),
    ]  # fmt: skip
    assert result.offsets[2] == pytest.approx(OFFSETS[2])


class ScriptedStdin:
    """``input()``'s stdin: answers Enter ``lines`` times, then ends (EOF) or raises
    KeyboardInterrupt (Ctrl-C)."""

    def __init__(self, lines: int, end: type[BaseException] = EOFError) -> None:
        self.lines, self.end = lines, end

    def readline(self) -> str:
        if self.lines <= 0:
            if self.end is EOFError:
                return ""
            raise self.end()
        self.lines -= 1
        return "\n"


@pytest.mark.parametrize(
    ("end", "code", "said"),
    [(EOFError, 2, "stdin closed"), (KeyboardInterrupt, 130, "interrupted")],
)
def test_stdin_closed_or_ctrl_c_is_one_line_and_the_saved_file_is_kept(
    end, code, said, twin, tmp_path, monkeypatch, capsys
):
    """``ergo calibrate joints`` with its arm (the twin mounted with offsets) and a user who
    stops after 4 Enters: one line saying where and that nothing was saved; the joints.json
    already there is untouched."""
    import calibration.cli as cli
    from explore.cli import main

    path = store.save("joints", "r1", JointCalibration(
        tuple(ergo_jr_spec().names), OFFSETS, DIRECTIONS, ergo_jr_spec().lower,
        ergo_jr_spec().upper,
    ).to_dict(), tmp_path)  # fmt: skip
    before = path.read_bytes()
    monkeypatch.setattr(cli, "_make_arm", lambda args: MountedArm(SimArm(twin)))
    monkeypatch.setattr("sys.stdin", ScriptedStdin(4, end))
    rc = main(["calibrate", "joints", "--rig-id", "r1", "--dir", str(tmp_path), "--port", "x"])
    err = capsys.readouterr().err.strip()
    assert rc == code and len(err.splitlines()) == 1, err
    # zero pose, m1 lower, m1 upper (not moved: told, asked again), m1 lower, then the end
    assert said in err and "at m1's upper limit" in err and f"{path} unchanged" in err
    assert path.read_bytes() == before
    assert not twin.torque_enabled()
