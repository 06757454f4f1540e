"""Hardware in the loop without hardware: the twin behind a real pseudo-terminal speaking
Protocol 2.0 (``sim.dynamixel.server.PtyBusServer`` in a thread), driven by ``DynamixelArm``
and the bus; plus the emulator's packet logic in-process, the MJPEG camera and the rig.

No assertion is on durations; loops that wait for physics are bounded by a count."""

from __future__ import annotations

import argparse
import subprocess
import sys
from collections.abc import Iterator
from contextlib import contextmanager

import cv2
import numpy as np
import pytest
import serial

from explore.rigs.clock import RealClock
from explore.rigs.rig import RigConfig, make_rig
from robot.dynamixel import protocol as proto
from robot.dynamixel.arm import DynamixelArm
from robot.dynamixel.bus import DynamixelBus, HardwareAlertError, ServoError
from robot.dynamixel.control_table import XL320
from robot.dynamixel.scan import scan_cli
from robot.errors import SafetyStop
from sim.dynamixel.emulator import DynamixelEmulator, FaultConfig
from sim.dynamixel.server import PtyBusServer
from sim.mjpeg_server import MjpegServer, TwinFrames
from sim.realtime import RealtimeLoop
from sim.twin import Twin

# Generous slack per exchange: the emulator shares two busy cores with the test and physics.
LATENCY_S = 0.05


@contextmanager
def hil(faults: FaultConfig | None = None, **kw) -> Iterator[tuple[Twin, DynamixelEmulator, str]]:
    """The twin in real time, six emulated XL-320 on a fresh pty; yields (twin, emulator, path)."""
    twin = Twin(render_size=(96, 96))
    emulator = DynamixelEmulator(twin, faults=faults, **kw)
    try:
        with RealtimeLoop(twin), PtyBusServer(emulator) as server:
            yield twin, emulator, server.path
    finally:
        twin.close()


def test_arm_tracks_a_trajectory_and_turns_torque_off_on_disconnect() -> None:
    with hil() as (_, emulator, port):
        arm = DynamixelArm(port, latency_s=LATENCY_S)
        with arm:
            assert arm.bus.return_delay_s == 0.0  # written at connect (torque was off)
            assert all(s.peek("return_delay_time") == 0 for s in emulator.servos.values())
            arm.set_torque(True)
            assert all(emulator.torque_states().values())
            start = arm.read().positions
            goal = start + np.array([0.4, 0.25, -0.3, 0.35, 0.2, -0.25])
            errors = []
            clock = RealClock()  # 40 Hz control, as on the rig
            for k in range(40):
                sent = arm.command(start + min(1.0, k / 30) * (goal - start))
                clock.advance(0.025)
                state = arm.read()
                errors.append(np.abs(state.positions - sent).max())
            for _ in range(200):  # let it settle (bounded by count, not by time)
                state = arm.read()
                if np.abs(state.positions - goal).max() < 0.03:
                    break
            assert np.abs(state.positions - goal).max() < 0.05
            assert max(errors) < 0.2  # lag behind a 0.5 rad/s ramp, never a runaway
            assert np.all(np.isfinite(state.loads)) and np.all(state.temperatures == 25.0)
            # what the servos were told is what the arm says it sent
            goals = XL320.steps_to_rad([s.peek("goal_position") for s in emulator.servos.values()])
            assert np.allclose(goals, arm.last_sent, atol=XL320.rad_per_step)
        assert not any(emulator.torque_states().values())


def test_directions_and_offsets_map_joint_to_servo_angles() -> None:
    with hil(start_torque=True) as (_, emulator, port):
        directions = [1, -1, 1, 1, -1, 1]
        offsets = [0.0, 0.1, 0.0, -0.2, 0.0, 0.0]
        with DynamixelArm(port, latency_s=LATENCY_S, directions=directions, offsets=offsets) as arm:
            sent = arm.command(arm.read().positions + 0.05)
            arm.read()  # a round trip: the emulator has handled the (unanswered) sync write
            steps = np.array([s.peek("goal_position") for s in emulator.servos.values()])
            servo = XL320.steps_to_rad(steps)
            assert np.allclose(
                servo, np.array(directions) * sent + offsets, atol=XL320.rad_per_step
            )
            # one position unit, what the settle lets a joint flicker by at rest
            assert np.allclose(arm.position_resolution, np.radians(300 / 1023), rtol=1e-3)


def test_eeprom_write_with_torque_on_is_an_access_error() -> None:
    with hil() as (_, _, port), DynamixelBus(port, latency_s=LATENCY_S) as bus:
        bus.write_register(1, "return_delay_time", 10)  # torque off: EEPROM writable
        bus.write_register(1, "torque_enable", 1)
        with pytest.raises(ServoError) as info:
            bus.write_register(1, "return_delay_time", 0)
        assert info.value.error.code == proto.ACCESS_ERROR
        assert bus.read_register(1, "return_delay_time") == 10


def _statuses_until(
    ser: serial.Serial, servo_id: int, limit: int = 2000
) -> list[proto.StatusPacket]:
    """Read status packets until one from ``servo_id`` arrives (bounded by ``limit`` reads)."""
    decoder = proto.Decoder()
    got: list[proto.StatusPacket] = []
    for _ in range(limit):
        got += [p for p in decoder.feed(ser.read(64)) if isinstance(p, proto.StatusPacket)]
        if any(p.id == servo_id for p in got):
            return got
    raise AssertionError(f"no status from {servo_id}; got {got}")


def test_broadcast_gets_no_reply_except_ping_sync_read_and_bulk_read() -> None:
    with hil() as (_, _, port), serial.Serial(port, 1_000_000, timeout=0.01) as ser:
        bcast = proto.BROADCAST_ID
        for pkt in (
            proto.write(bcast, XL320.reg("led").address, b"\x01"),
            proto.read(bcast, 0, 2),
            proto.sync_write(30, 2, {1: b"\x00\x02"}),
            proto.reboot(bcast),
            proto.ping(1),  # a marker: the emulator answers in order
        ):
            ser.write(pkt.encode())
        # every reply before the marker's would be a reply to a broadcast
        assert [p.id for p in _statuses_until(ser, 1)] == [1]

        ser.write(proto.ping(bcast).encode())
        assert [p.id for p in _statuses_until(ser, 6)] == [1, 2, 3, 4, 5, 6]
        ser.write(proto.sync_read(0, 2, [2, 5]).encode())
        assert [p.id for p in _statuses_until(ser, 5)] == [2, 5]
        ser.write(proto.bulk_read([(4, 0, 2), (3, 3, 1)]).encode())
        replies = _statuses_until(ser, 3)
        assert [(p.id, p.params) for p in replies] == [(4, b"\x5e\x01"), (3, b"\x03")]


def test_overload_stops_the_arm_with_torque_off() -> None:
    faults = FaultConfig(overload_servo=3, overload_after_s=0.3)
    with hil(faults) as (_, emulator, port):
        arm = DynamixelArm(port, latency_s=LATENCY_S)
        with arm:
            arm.set_torque(True)
            q = arm.read().positions
            with pytest.raises(SafetyStop) as info:
                for k in range(2000):  # bounded: the overload trips after 0.3 s of torque
                    arm.command(q + 0.2 * np.sin(k / 20.0))
                    arm.read()
            cause = info.value.__cause__
            assert isinstance(cause, HardwareAlertError)
            assert (cause.servo_id, cause.bits) == (3, ["overload"])
            assert "overload" in str(info.value) and "\n" not in str(info.value)
            assert not arm.torque_enabled
            assert not any(emulator.torque_states().values())


def test_overload_at_torque_on_is_a_safety_stop_too() -> None:
    faults = FaultConfig(overload_servo=2, overload_after_s=0.0)
    with hil(faults) as (_, emulator, port), DynamixelArm(port, latency_s=LATENCY_S) as arm:
        with pytest.raises(SafetyStop):
            arm.set_torque(True)
        assert not arm.torque_enabled
        assert not any(emulator.torque_states().values())


def test_dropped_and_corrupted_replies_are_absorbed_by_retries() -> None:
    faults = FaultConfig(drop_rate=0.1, corrupt_rate=0.1, seed=3)
    # 30 ms of slack per exchange: at 10 ms, 7 timeouts in a row were seen at load 10
    with hil(faults) as (_, _, port), DynamixelArm(port, latency_s=0.03, retries=6) as arm:
        for _ in range(20):
            assert np.all(np.isfinite(arm.read().positions))
        c = arm.bus.counters
        assert c.retries > 0 and (c.timeouts > 0 or c.crc_errors > 0)


def test_scan_cli_over_the_pty(capsys) -> None:
    with hil() as (_, _, port):
        code = scan_cli(argparse.Namespace(port=port, baud=1_000_000, ids=[0, 1, 2, 3, 4, 5, 6, 7]))
    out = capsys.readouterr().out.splitlines()
    assert code == 0
    assert [line.split()[0] for line in out[1:]] == ["1", "2", "3", "4", "5", "6"]
    assert "XL-320" in out[1] and "firmware 29" in out[1]


# ---- the emulator's packet logic, in-process ---------------------------------------------------
def test_corrupt_instruction_gets_a_crc_error_status() -> None:
    emulator = DynamixelEmulator(None)
    wire = bytearray(proto.read(2, 0, 2).encode())
    wire[-1] ^= 0xFF
    [(_, reply)] = emulator.handle_bytes(bytes(wire))
    [status] = proto.decode_all(reply)
    assert (status.id, status.error_code) == (2, proto.CRC_ERROR)


def test_return_delay_is_honoured_in_order() -> None:
    emulator = DynamixelEmulator(None)  # factory return delay 250 = 500 us per servo
    replies = emulator.handle(proto.sync_read(37, 2, [1, 2, 3]))
    assert [d for d, _ in replies] == pytest.approx([500e-6, 1000e-6, 1500e-6])
    for s in emulator.servos.values():
        s.poke("return_delay_time", 0)
    assert [d for d, _ in emulator.handle(proto.sync_read(37, 2, [1, 2, 3]))] == [0.0] * 3


@pytest.mark.parametrize(
    ("address", "data", "code"),
    [
        (37, b"\x00\x02", proto.ACCESS_ERROR),  # read-only
        (30, b"\x00", proto.DATA_LENGTH_ERROR),  # half of goal position
        (30, b"\x00\x04", proto.DATA_LIMIT_ERROR),  # 1024 > 1023
        (60, b"\x00", proto.DATA_RANGE_ERROR),  # outside the table
        (25, b"\x01", 0),  # LED
    ],
)
def test_write_errors(address: int, data: bytes, code: int) -> None:
    emulator = DynamixelEmulator(None)
    [(_, reply)] = emulator.handle(proto.write(1, address, data))
    assert proto.decode_all(reply)[0].error_code == code


def test_status_return_level_one_answers_reads_only() -> None:
    emulator = DynamixelEmulator(None)
    emulator.handle(proto.write(1, XL320.reg("status_return_level").address, b"\x01"))
    assert emulator.handle(proto.write(1, 25, b"\x01")) == []
    assert len(emulator.handle(proto.read(1, 25, 1))) == 1


# ---- camera, rig and the command -------------------------------------------------------------
def test_mjpeg_stream_opens_in_opencv() -> None:
    twin = Twin(render_size=(64, 64))
    try:
        with MjpegServer(TwinFrames(twin), fps=20) as server:
            assert server.url.startswith("http://127.0.0.1:")
            cap = cv2.VideoCapture(server.url)
            try:
                assert cap.isOpened()
                ok, frame = cap.read()
                assert ok and frame.shape == (64, 64, 3)
            finally:
                cap.release()
    finally:
        twin.close()


def test_twin_serve_prints_its_pty_and_camera_and_answers() -> None:
    cmd = [sys.executable, "-m", "explore.cli", "twin", "serve", "--bus", "dynamixel"]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        first = proc.stdout.readline().strip()
        second = proc.stdout.readline().strip()
        assert first.startswith("dynamixel bus on /dev/"), (first, proc.stderr.read())
        assert second.startswith("camera on http://127.0.0.1:")
        with DynamixelBus(first.split()[-1], latency_s=LATENCY_S, retries=5) as bus:
            assert bus.ping(6).model_number == 350
    finally:
        proc.terminate()
        proc.wait(timeout=10)


def test_rig_runs_against_the_emulated_arm_and_camera() -> None:
    with hil() as (twin, emulator, port), MjpegServer(TwinFrames(twin), fps=20) as camera:
        rig = make_rig(
            RigConfig(name="dynamixel", rig_id="hil", options={"port": port, "camera": camera.url})
        )
        assert type(rig.sensor).__name__ == "CameraSensor" and isinstance(rig.arm, DynamixelArm)
        rig.arm.bus.latency_s = LATENCY_S
        with rig:
            assert all(emulator.torque_states().values())
            frame = rig.camera.read()
            assert frame.image.shape == (96, 96, 3)
            rig.arm.command(rig.arm.read().positions + 0.05)
            rig.clock.advance(0.025)
        assert not any(emulator.torque_states().values())
