"""The Dynamixel bus: retries counted per call, typed errors, timeouts from the baud rate.

Runs over pyserial's ``loop://`` (nothing answers but our own echo) and over an in-process
fake serial port backed by the packet logic of the emulator (no twin, no pty)."""

from __future__ import annotations

import argparse
import os
import time

import numpy as np
import pytest

from robot.dynamixel import protocol as proto
from robot.dynamixel.arm import DynamixelArm
from robot.dynamixel.bus import (
    CorruptPacketError,
    DynamixelBus,
    HardwareAlertError,
    NoStatusError,
    ServoError,
)
from robot.dynamixel.control_table import XL320, XL330_M288
from robot.dynamixel.scan import SCAN_LATENCY_S, scan, scan_cli
from robot.errors import BusError
from sim.dynamixel.emulator import DynamixelEmulator, EmulatedSerial, FaultConfig

# Short slack: the fake answers in-process, so a lost reply costs only this long.
LATENCY_S = 0.005


def fake_bus(faults: FaultConfig | None = None, retries: int = 2, echo: bool = True):
    emulator = DynamixelEmulator(None, faults=faults)
    bus = DynamixelBus(
        "fake",
        retries=retries,
        latency_s=LATENCY_S,
        return_delay_s=0.0,
        connection=EmulatedSerial(emulator, echo=echo),
    )
    return bus, emulator


def test_loopback_echo_only_gives_no_status_after_the_retries() -> None:
    with DynamixelBus("loop://", retries=2, latency_s=LATENCY_S) as bus:
        with pytest.raises(NoStatusError) as info:
            bus.ping(1)
        assert info.value.ids == [1]
        assert "\n" not in str(info.value)
        assert bus.counters.timeouts == 3
        assert bus.counters.retries == 2
        assert bus.last_call_retries == 2
        assert bus.counters.crc_errors == 0  # the echo is a valid instruction packet


def test_missing_port_is_a_one_line_bus_error() -> None:
    with pytest.raises(BusError, match="no such port") as info:
        DynamixelBus("/dev/ttyDOES_NOT_EXIST", retries=0).open()
    assert "\n" not in str(info.value)


def test_bad_baud_and_retries_are_refused() -> None:
    with pytest.raises(BusError, match="baud"):
        DynamixelBus("loop://", baud=0)
    with pytest.raises(BusError, match="retries"):
        DynamixelBus("loop://", retries=-1)


def test_timeout_follows_baud_bytes_and_return_delay() -> None:
    bus = DynamixelBus("x", baud=1_000_000, latency_s=0.0, return_delay_s=0.0)
    # 20-byte sync read + six 15-byte statuses = 110 bytes = 1100 bits at 1 Mbps
    assert bus.timeout_for(20, [4] * 6) == pytest.approx(1.1e-3)
    slow = DynamixelBus("x", baud=57_600, latency_s=0.002, return_delay_s=500e-6)
    assert slow.timeout_for(10, [3]) == pytest.approx(24 * 10 / 57_600 + 500e-6 + 0.002)


def test_ping_read_write_sync_and_bulk_through_the_fake() -> None:
    bus, _ = fake_bus()
    reply = bus.ping(3)
    assert (reply.id, reply.model_number, reply.firmware) == (3, 350, 29)
    bus.write_register(2, "goal_position", 700)
    assert bus.read_register(2, "goal_position") == 700
    bus.sync_write(30, 2, {1: XL320.reg("goal").encode(600), 4: XL320.reg("goal").encode(300)})
    data = bus.sync_read(30, 2, [1, 4])
    assert {k: XL320.reg("goal").decode(v) for k, v in data.items()} == {1: 600, 4: 300}
    bulk = bus.bulk_read([(1, 3, 1), (5, 0, 2)])
    assert bulk == {1: b"\x01", 5: (350).to_bytes(2, "little")}
    assert bus.counters.retries == 0 and bus.counters.timeouts == 0


def test_servo_error_is_typed_decoded_and_not_retried() -> None:
    bus, _ = fake_bus()
    with pytest.raises(ServoError) as info:
        bus.write(1, XL320.reg("present_position").address, b"\x00\x02")  # read-only
    assert info.value.servo_id == 1
    assert info.value.error.code == proto.ACCESS_ERROR
    assert "access error" in str(info.value)
    assert bus.counters.servo_errors == 1 and bus.counters.retries == 0


def test_lost_replies_are_retried_and_counted() -> None:
    bus, _ = fake_bus(FaultConfig(drop_rate=0.3, seed=1), retries=8)
    for _ in range(10):
        data = bus.sync_read(3, 1, [1, 2, 3, 4, 5, 6])  # the id register
        assert {k: v[0] for k, v in data.items()} == {i: i for i in range(1, 7)}
    assert bus.counters.timeouts > 0
    assert bus.counters.retries >= bus.counters.timeouts


def test_corrupt_replies_give_corrupt_packet_error_after_the_retries() -> None:
    bus, _ = fake_bus(FaultConfig(corrupt_rate=1.0, seed=2), retries=1)
    with pytest.raises(CorruptPacketError) as info:
        bus.read(1, 0, 2)
    assert info.value.ids == [1]
    assert bus.counters.crc_errors >= 2
    assert bus.counters.retries == 1


def test_hardware_alert_reads_and_decodes_the_error_status() -> None:
    bus, emulator = fake_bus(FaultConfig(overload_servo=2, overload_after_s=0.0))
    bus.write_register(2, "torque_enable", 1)  # the overload trips once torque is on
    with pytest.raises(HardwareAlertError) as info:
        bus.sync_read(37, 2, [1, 2, 3])
    err = info.value
    assert (err.servo_id, err.hardware_status, err.bits) == (2, 1, ["overload"])
    assert set(err.data) == {1, 2, 3}  # what was read is still handed over
    assert emulator.torque_states()[2] is False  # shutdown on overload
    assert bus.counters.alerts == 1
    bus.reboot(2)
    assert bus.hardware_error(2) == 0


def test_broadcast_write_expects_no_reply() -> None:
    bus, emulator = fake_bus()
    bus.write(proto.BROADCAST_ID, XL320.reg("led").address, b"\x01")
    assert bus.counters.timeouts == 0
    assert all(s.peek("led") == 1 for s in emulator.servos.values())


def test_scan_finds_the_six_servos() -> None:
    bus, _ = fake_bus(retries=0)
    found = scan(bus, list(range(10)))
    assert [r.id for r in found] == [1, 2, 3, 4, 5, 6]
    assert {r.model_number for r in found} == {350}


def test_scan_looks_again_slowly_at_the_arms_ids_that_answered_late() -> None:
    """Replies 50 ms late miss the quick sweep's slack (20 ms, as ``ergo bus scan``); the
    arm's ids are asked again with more slack and found, the others are not asked twice."""
    bus, _ = fake_bus(FaultConfig(extra_delay_s=0.05), retries=0)
    bus.latency_s = SCAN_LATENCY_S
    bus.latency.cap = SCAN_LATENCY_S  # no adapting during the sweep: every reply misses it
    assert scan(bus, list(range(10))) == []
    bus.latency.cap = 1.0
    found = scan(bus, list(range(10)), again=[1, 2, 3, 4, 5, 6])
    assert [r.id for r in found] == [1, 2, 3, 4, 5, 6]


def test_scan_cli_reports_a_bad_port_in_one_line(capsys) -> None:
    args = argparse.Namespace(port="/dev/ttyDOES_NOT_EXIST", baud=1_000_000, ids=[1])
    assert scan_cli(args) == 2
    err = capsys.readouterr().err
    assert err.startswith("ergo: error: cannot open Dynamixel bus") and err.count("\n") == 1


def test_busy_port_is_a_one_line_bus_error() -> None:
    master, slave = os.openpty()
    try:
        path = os.ttyname(slave)
        with DynamixelBus(path, retries=0), pytest.raises(BusError, match="port busy"):
            DynamixelBus(path, retries=0).open()
    finally:
        os.close(master)
        os.close(slave)


def test_arm_refuses_servos_of_another_model() -> None:
    emulator = DynamixelEmulator(None, model=XL330_M288)
    arm = DynamixelArm("fake", connection=EmulatedSerial(emulator), latency_s=LATENCY_S)
    with pytest.raises(BusError, match=r"model 1200 \(XL-330-M288\), expected 350"):
        arm.connect()


def test_arm_on_xl330_servos_round_trips_positions() -> None:
    emulator = DynamixelEmulator(None, model=XL330_M288)
    arm = DynamixelArm(
        "fake",
        model="XL-330-M288",
        directions=[1, -1, 1, -1, 1, 1],
        connection=EmulatedSerial(emulator),
        latency_s=LATENCY_S,
    )
    with arm:
        arm.set_torque(True)
        q = np.array([0.1, -0.1, 0.12, 0.05, -0.02, 0.0])
        sent = arm.command(q)
        state = arm.read()  # the fake is an ideal servo: present = goal
        assert np.allclose(state.positions, sent, atol=XL330_M288.rad_per_step)
        assert np.all(np.isfinite(state.loads))
    assert not any(emulator.torque_states().values())


def test_a_reading_is_stamped_when_its_request_left_not_when_its_replies_came() -> None:
    """A servo samples what it reports as it reads the request; the replies then wait in the
    adapter (here 30 ms, an FTDI's latency timer): the reading's time is the request's."""
    delay = 0.03
    emulator = DynamixelEmulator(None, faults=FaultConfig(extra_delay_s=delay))
    arm = DynamixelArm("fake", connection=EmulatedSerial(emulator), latency_s=0.05)
    with arm:
        for _ in range(3):
            before = time.monotonic()
            state = arm.read()
            after = time.monotonic()
            assert before <= state.timestamp <= after - delay, (before, state.timestamp, after)
