"""A physical rig opened with ``--rig-id X`` reads X's ``joints.json``: its arm gets the file's
offsets and directions and clamps every command to the tighter of the spec's and the file's
limits (property-tested through ``DynamixelArm`` over the emulated servos); a damaged or
foreign file, hand-typed options that disagree with it, and a physical rig without its own id
are refused in one line."""

from __future__ import annotations

import json
import logging
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from calibration import store
from calibration.joints import JointCalibration
from explore.cli import main
from explore.rigs.canopen import can_offsets
from explore.rigs.hardware import HardwareOptions, joint_setup
from explore.rigs.rig import RigConfig, RigError, make_rig
from robot.canopen.units import JointScaling
from robot.dynamixel.arm import DynamixelArm
from robot.dynamixel.control_table import XL320
from robot.spec import ergo_jr_spec
from sim.dynamixel.emulator import DynamixelEmulator, EmulatedSerial

SPEC = ergo_jr_spec()
OFFSETS = np.radians([10.0, -25.0, 40.0, 0.0, 5.0, -3.0])  # servo angle at joint zero
DIRECTIONS = np.array([1.0, -1.0, 1.0, -1.0, 1.0, 1.0])
LOWER = np.radians([-100.0, -60.0, -80.0, -170.0, -45.0, -30.0])  # m4's passes the spec's
UPPER = np.radians([100.0, 80.0, 70.0, 120.0, 45.0, 30.0])


def calibration(**changes) -> dict:
    data = JointCalibration(tuple(SPEC.names), OFFSETS, DIRECTIONS, LOWER, UPPER).to_dict()
    data.update(changes)
    return data


def rig(name: str = "dynamixel", rig_id: str = "bench", **options) -> RigConfig:
    bus = {"port": "/dev/pts/99"} if name == "dynamixel" else {"can": "slcan:/dev/pts/99"}
    return RigConfig(name, rig_id, {**bus, "camera": "0", **options})


@pytest.mark.parametrize("name", ["dynamixel", "canopen"])
def test_a_physical_rig_applies_its_joint_calibration(name):
    store.save("joints", "bench", calibration())
    arm = make_rig(rig(name)).arm
    np.testing.assert_allclose(arm.spec.lower, np.maximum(LOWER, SPEC.lower))
    np.testing.assert_allclose(arm.spec.upper, np.minimum(UPPER, SPEC.upper))
    assert arm.spec.lower[3] == SPEC.lower[3]  # the tighter of the two: never widened
    if name == "dynamixel":
        np.testing.assert_array_equal(arm.directions, DIRECTIONS)
        np.testing.assert_allclose(arm.offsets, OFFSETS)
    else:  # CanArm's offset is the joint angle at drive position 0
        np.testing.assert_allclose(arm.config.offsets, -DIRECTIONS * OFFSETS)


def test_the_canopen_offsets_map_a_drive_angle_to_the_calibrated_joint_angle():
    """``CanArm``'s scaling with ``can_offsets`` gives the joint angle the calibration's
    convention (servo = direction * joint + offset) gives, for any drive angle."""
    cpr = np.full(6, 4096.0)
    scaling = JointScaling(cpr, DIRECTIONS, can_offsets(DIRECTIONS, OFFSETS))
    cal = JointCalibration(tuple(SPEC.names), OFFSETS, DIRECTIONS, LOWER, UPPER)
    counts = np.array([-900, 300, 0, 1200, -40, 77])
    drive_rad = counts * 2 * math.pi / cpr
    np.testing.assert_allclose(scaling.to_rad(counts), cal.to_joint(drive_rad), atol=1e-12)


@pytest.mark.parametrize(
    ("damage", "why"),
    [
        (lambda text: "{not json", "not valid JSON"),
        (lambda text: text.replace('"offsets": [', '"offsets": [NaN, ', 1), "offsets"),
        (lambda text: text.replace('"version": 1', '"version": 2'), "newer than this program"),
        (lambda text: text.replace('"kind": "joints"', '"kind": "arena"'), "field 'kind'"),
    ],
)
def test_a_damaged_joints_json_is_refused_in_one_line_naming_it(damage, why):
    path = store.save("joints", "bench", calibration())
    path.write_text(damage(path.read_text()))
    with pytest.raises(RigError) as caught:
        make_rig(rig())
    message = str(caught.value)
    assert str(path) in message and why in message and "\n" not in message


def test_a_joints_json_for_other_joints_or_out_of_range_is_refused_naming_it():
    four = calibration(
        names=["m1", "m2", "m3", "m4"], offsets=[0.0] * 4, directions=[1] * 4,
        lower=[-1.0] * 4, upper=[1.0] * 4,
    )  # fmt: skip
    path = store.save("joints", "bench", four)
    with pytest.raises(RigError, match=r"calibrates joints m1, m2, m3, m4, the arm has m1, m2, m3"):
        make_rig(rig())
    outside = calibration(lower=[*LOWER[:5], 1.7], upper=[*UPPER[:5], 1.9])  # m6 stops at 90 deg
    store.save("joints", "bench", outside)
    with pytest.raises(RigError, match=rf"{path}: joint m6's range 97..109 deg lies outside"):
        make_rig(rig())


def test_a_garbage_joints_json_stops_ergo_explore_in_one_line(capsys):
    path = store.calibration_path("joints", "bench")
    path.parent.mkdir(parents=True)
    path.write_bytes(b"\x00\xffgarbage")
    args = ["explore", "--rig", "dynamixel", "--rig-id", "bench", "--port", "/dev/pts/99",
            "--camera", "0", "--episodes", "1", "--no-progress", "--rerun", "off"]  # fmt: skip
    assert main(args) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("ergo: error: ") and str(path) in err and len(err.splitlines()) == 1


def test_hand_typed_offsets_that_differ_from_the_file_are_refused_unless_told_which_wins():
    store.save("joints", "bench", calibration())
    with pytest.raises(RigError, match="joint_calibration=none") as caught:
        make_rig(rig(offsets=[0.0] * 6))
    assert "rig option offsets" in str(caught.value) and "joints.json" in str(caught.value)
    # the same values as the file: no conflict
    arm = make_rig(rig(offsets=OFFSETS.tolist(), directions=DIRECTIONS.tolist())).arm
    np.testing.assert_allclose(arm.offsets, OFFSETS)
    # a whole turn apart is the same zero mark (robot.angles): the file's offsets are used
    turned = (OFFSETS + np.array([2 * np.pi, 0, -2 * np.pi, 0, 4 * np.pi, 0])).tolist()
    arm = make_rig(rig(offsets=turned, directions=DIRECTIONS.tolist())).arm
    np.testing.assert_allclose(arm.offsets, OFFSETS)
    with pytest.raises(RigError, match="rig option offsets"):  # half a turn is not
        make_rig(rig(offsets=(OFFSETS + np.pi).tolist(), directions=DIRECTIONS.tolist()))
    # the user says the options win: no file read, the spec's limits
    arm = make_rig(rig(offsets=[0.0] * 6, joint_calibration="none")).arm
    np.testing.assert_array_equal(arm.offsets, np.zeros(6))
    np.testing.assert_array_equal(arm.spec.lower, SPEC.lower)


def test_no_joints_json_is_one_warning_and_the_spec_limits(caplog):
    with caplog.at_level(logging.WARNING, logger="explore.rigs.hardware"):
        arm = make_rig(rig()).arm
    assert [r.getMessage() for r in caplog.records if "no joint calibration" in r.getMessage()]
    np.testing.assert_array_equal(arm.spec.lower, SPEC.lower)


@pytest.mark.parametrize("name", ["dynamixel", "canopen"])
def test_a_physical_rig_without_its_own_id_is_refused_in_one_line(name, capsys):
    with pytest.raises(RigError, match="needs its own id: give --rig-id ID"):
        make_rig(rig(name, rig_id="twin"))
    bus = ["--port", "/dev/pts/99"] if name == "dynamixel" else ["--can", "slcan:/dev/pts/99"]
    assert main(["explore", "--rig", name, *bus, "--episodes", "1", "--no-progress"]) == 2
    err = capsys.readouterr().err.strip()
    assert "--rig-id ID" in err and len(err.splitlines()) == 1


# ---- the property: calibrated limits hold for every command --------------------------------
HALF_UNIT = XL320.rad_per_step / 2  # goals are rounded to the servo's position unit


@st.composite
def calibrations(draw):
    """A joint calibration whose limits lie inside the spec's, with a pose inside them."""
    offsets = np.array(draw(st.lists(st.floats(-0.8, 0.8), min_size=6, max_size=6)))
    directions = np.array(draw(st.lists(st.sampled_from([-1.0, 1.0]), min_size=6, max_size=6)))
    a = np.array(draw(st.lists(st.floats(0.0, 1.0), min_size=6, max_size=6)))
    b = np.array(draw(st.lists(st.floats(0.0, 1.0), min_size=6, max_size=6)))
    # limits within the servo's reach too: |direction * q + offset| <= 150 deg
    reach = np.radians(150.0) - np.abs(offsets)
    lo_bound, hi_bound = np.maximum(SPEC.lower, -reach), np.minimum(SPEC.upper, reach)
    lo = lo_bound + np.minimum(a, b) * 0.9 * (hi_bound - lo_bound)
    hi = lo + 0.05 + np.abs(a - b) * 0.9 * (hi_bound - lo)
    hi = np.minimum(hi, hi_bound)
    start = lo + np.array(draw(st.lists(st.floats(0.0, 1.0), min_size=6, max_size=6))) * (hi - lo)
    return JointCalibration(tuple(SPEC.names), offsets, directions, lo, hi), start


commands = st.lists(st.lists(st.floats(-6.0, 6.0), min_size=6, max_size=6), min_size=1, max_size=30)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(cal_start=calibrations(), targets=commands)
def test_a_calibrated_rig_never_commands_a_servo_outside_the_calibrated_limits(
    cal_start, targets, tmp_path_factory
):
    """Any commands (up to 6 rad off, far past every limit) through the rig's ``DynamixelArm``
    built by ``joint_setup`` from a joints.json: every goal the emulated servos receive,
    turned back into a joint angle, lies within the calibrated limits (to half a position
    unit, 0.0026 rad: goals are whole units)."""
    cal, start = cal_start
    folder = tmp_path_factory.mktemp("cal")
    path = store.save("joints", "prop", cal.to_dict(), folder)
    config = RigConfig("dynamixel", "prop", {"joint_calibration": str(path)})
    setup = joint_setup(config, HardwareOptions())
    emulator = DynamixelEmulator(None)
    for k, servo in enumerate(emulator.servos.values()):  # the arm at rest inside its limits
        steps = int(XL320.rad_to_steps(cal.to_servo(start)[k]))
        servo.poke("goal", steps)
        servo.poke("position", steps)
    arm = DynamixelArm(
        "emulated", spec=setup.spec, directions=setup.directions, offsets=setup.offsets,
        connection=EmulatedSerial(emulator),
    )  # fmt: skip
    with arm:
        arm.set_torque(True)
        for target in targets:
            arm.command(np.array(target))
            goals = np.array([s.peek("goal") for s in emulator.servos.values()])
            joint = cal.directions * (XL320.steps_to_rad(goals) - cal.offsets)
            assert np.all(joint >= cal.lower - HALF_UNIT - 1e-9), (joint, cal.lower)
            assert np.all(joint <= cal.upper + HALF_UNIT + 1e-9), (joint, cal.upper)


def test_the_joint_calibration_file_recorded_is_the_one_read(tmp_path):
    """``joint_calibration=FILE`` names another file than the rig id's."""
    path = store.save("joints", "elsewhere", calibration(), tmp_path)
    setup = joint_setup(rig(joint_calibration=str(path)), HardwareOptions())
    assert setup.path == path
    assert json.loads(path.read_text())["kind"] == "joints"
