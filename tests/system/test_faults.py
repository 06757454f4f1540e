"""Faults on the emulated Dynamixel bus, end to end through DynamixelArm and the run loop:
lost and corrupt replies (bounded retries, counted), a servo that stops answering and an
overload alert (safe stop: torque off, one-line error), and a short soak that resumes after
each failure and loses no completed episode."""

from __future__ import annotations

import numpy as np
import pytest

from robot.dynamixel.arm import DynamixelArm
from robot.dynamixel.bus import NoStatusError
from robot.errors import RobotError, SafetyStop
from sim.dynamixel.emulator import DynamixelEmulator, EmulatedSerial, FaultConfig

LATENCY_S = 0.002


def _arm(faults: FaultConfig | None = None) -> tuple[DynamixelArm, DynamixelEmulator]:
    emulator = DynamixelEmulator(None, faults=faults)
    arm = DynamixelArm("emulated", connection=EmulatedSerial(emulator), latency_s=LATENCY_S)
    return arm, emulator


def test_lost_and_corrupt_replies_are_retried_and_counted():
    arm, _ = _arm(FaultConfig(drop_rate=0.05, corrupt_rate=0.05, seed=3))
    with arm:
        arm.set_torque(True)
        failures = 0
        for k in range(200):
            try:
                arm.command(np.full(6, 0.001 * k))
                arm.read()
            except NoStatusError:
                failures += 1
    c = arm.bus.counters
    assert c.retries > 0 and c.timeouts > 0 and c.crc_errors > 0
    # with 10% bad replies and 2 retries, a call fails about 0.1**3 of the time
    assert failures <= 5, (failures, c.as_dict())


def test_a_servo_that_stops_answering_is_a_one_line_error_naming_it():
    arm, emulator = _arm()
    with arm:
        arm.set_torque(True)
        del emulator.servos[4]  # servo 4 unplugged
        with pytest.raises(RobotError) as exc:
            for _ in range(3):
                arm.read()
        msg = str(exc.value)
        assert "\n" not in msg and "4" in msg, msg
    # disconnect still turned the others' torque off
    assert not any(emulator.torque_states().values())


def test_an_overload_alert_stops_the_arm_with_torque_off():
    arm, emulator = _arm(FaultConfig(overload_servo=2, overload_after_s=0.0))
    with arm, pytest.raises((SafetyStop, RobotError)) as exc:
        arm.set_torque(True)
        for _ in range(20):
            arm.command(np.zeros(6))
            arm.read()
    assert "2" in str(exc.value) and "\n" not in str(exc.value)
    assert not any(emulator.torque_states().values())


@pytest.mark.slow
def test_a_short_soak_over_the_serial_bus_loses_no_episode(tmp_path):
    from testkit.fault_soak import soak

    result = soak(episodes=15, rate=0.05, bus="serial", seed=1, out=tmp_path / "run")
    print("\n", result)
    assert result["lost_episodes"] == 0 and result["history_ok"]
    assert result["counters"]["bus_retries"] > 0


def test_a_short_soak_with_arm_level_faults_loses_no_episode(tmp_path):
    from testkit.fault_soak import soak

    result = soak(episodes=15, rate=0.01, bus="arm", seed=2, out=tmp_path / "run")
    print("\n", result)
    assert result["lost_episodes"] == 0 and result["history_ok"]
    assert result["failed_attempts"] >= 1  # 1% of ~2000 arm calls: some episodes failed
