"""The twin's servo dynamics as data (sim/servo_model.py) and how the twin applies them."""

from __future__ import annotations

import numpy as np
import pytest

from sim.servo_model import NOMINAL, ServoModel, ServoModelError
from sim.twin import Twin


def test_nominal_is_what_the_mjcf_file_loads() -> None:
    assert Twin(render_size=(16, 16)).servos == NOMINAL


def test_a_servo_model_round_trips_through_a_dict() -> None:
    model = NOMINAL.replace(kp=[3.0, 3.1, 3.2, 3.3, 3.4, 3.5], delay_s=0.02)
    assert ServoModel.from_dict(model.to_dict()) == model


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"kp": [1.0] * 5}, "kp needs 6 values"),
        ({"damping": [0.1] * 5 + [float("nan")]}, "damping must be finite"),
        ({"kp": [0.0] * 6}, "kp must be > 0"),
        ({"frictionloss": [-0.1] * 6}, "frictionloss must be >= 0"),
        ({"delay_s": 3.0}, "delay_s must be a number in"),
    ],
)
def test_a_bad_servo_model_is_one_line(changes: dict, message: str) -> None:
    with pytest.raises(ServoModelError, match=message) as info:
        NOMINAL.replace(**changes)
    assert "\n" not in str(info.value)


def test_unknown_and_missing_fields_are_refused() -> None:
    with pytest.raises(ServoModelError, match="unknown field"):
        ServoModel.from_dict({**NOMINAL.to_dict(), "kd": [1] * 6})
    data = NOMINAL.to_dict()
    del data["armature"]
    with pytest.raises(ServoModelError, match="missing field"):
        ServoModel.from_dict(data)


def _step_response(twin: Twin, step: float = 0.5, seconds: float = 0.4) -> np.ndarray:
    """m3's angle every 5 ms after a step target of ``step`` rad, shape (n,), rad."""
    twin.set_targets(np.array([0, 0, step, 0, 0, 0]))
    out = []
    for _ in range(round(seconds / twin.timestep)):
        twin.step()
        out.append(twin.joint_positions()[2])
    return np.array(out)


def test_the_twin_moves_with_the_servo_model_it_was_given() -> None:
    stiff = NOMINAL.replace(kp=[7.0] * 6)
    twin = Twin(render_size=(16, 16), servos=stiff)
    assert twin.servos == stiff
    # a step small enough not to saturate the 0.39 N.m ceiling: twice the gain rises sooner
    fast = _step_response(twin, step=0.05)
    slow = _step_response(Twin(render_size=(16, 16)), step=0.05)
    assert np.argmax(fast > 0.045) < np.argmax(slow > 0.045)
    twin.set_torque(False)
    twin.set_torque(True)  # torque back on restores the given gain, not the file's
    assert twin.servos.kp == (7.0,) * 6
    np.testing.assert_allclose(twin.model.actuator_gainprm[twin._act_idx, 0], 7.0)


def test_a_transport_delay_shifts_the_response_by_the_delay() -> None:
    delay = 0.03  # 6 physics steps
    delayed = _step_response(Twin(render_size=(16, 16), servos=NOMINAL.replace(delay_s=delay)))
    plain = _step_response(Twin(render_size=(16, 16)))
    k = round(delay / 0.005)
    np.testing.assert_allclose(delayed[: k - 1], 0.0, atol=1e-9)
    np.testing.assert_allclose(delayed[k:], plain[:-k], atol=1e-9)


def test_targets_are_the_latest_given_and_applied_targets_what_the_actuators_hold() -> None:
    twin = Twin(render_size=(16, 16), servos=NOMINAL.replace(delay_s=0.02))
    q = np.array([0.1, 0.2, 0.3, 0, 0, 0])
    twin.set_targets(q)
    np.testing.assert_array_equal(twin.targets(), q)
    np.testing.assert_array_equal(twin.applied_targets(), 0.0)
    twin.step(0.02)
    np.testing.assert_array_equal(twin.applied_targets(), q)
    twin.set_targets(2 * q)
    twin.reset()  # a reset drops commands still in flight
    twin.step(0.05)
    np.testing.assert_array_equal(twin.applied_targets(), 0.0)


def _dynamics_payload(servos: ServoModel) -> dict:
    return {
        "servos": servos.to_dict(),
        "recording": {"path": "r.npz", "sha256": "0" * 64},
        "held_out_rms_rad": {"nominal": 0.02, "fitted": 0.004},
    }


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("kp", 1e300),
        ("damping", 50.0),
        ("armature", 1.0),
        ("frictionloss", 5.0),
        ("force_limit", 1e-6),
    ],
)
def test_a_dynamics_payload_out_of_range_is_one_line_naming_the_field(field, value):
    from plumbing.fields import Fields
    from robot.calibration_files import CalibrationError
    from sim.servo_model import check_dynamics

    payload = _dynamics_payload(NOMINAL.replace(**{field: [value] * 6}))
    with pytest.raises(CalibrationError) as info:
        check_dynamics(Fields("dynamics.json: data", payload, CalibrationError, name="data"))
    message = str(info.value)
    assert "\n" not in message and field in message and "nominal" in message


def test_the_stand_ins_servos_and_the_nominal_pass_the_dynamics_check():
    from plumbing.fields import Fields
    from robot.calibration_files import CalibrationError
    from sim.servo_model import check_dynamics
    from sim.standin.hidden import draw_hidden

    for servos in [NOMINAL, *(draw_hidden(seed).servos for seed in range(300, 320))]:
        payload = _dynamics_payload(servos)
        assert check_dynamics(Fields("d", payload, CalibrationError, name="data")) == servos
