"""The SLCAN adapter emulated on a pty (``sim.canopen.server.SlcanPtyBridge``), seen by a
client on its serial port: what it keeps and what it drops of the bytes queued for the host."""

from __future__ import annotations

import time
import uuid
from collections.abc import Iterator

import can
import pytest
import serial

from sim.canopen.server import SlcanPtyBridge

BOUND_S = 5.0  # a bound against hangs, not an expectation


@pytest.fixture
def bridge_and_bus() -> Iterator[tuple[SlcanPtyBridge, can.BusABC]]:
    channel = f"bridge-{uuid.uuid4().hex[:8]}"
    bridge_side = can.Bus(interface="virtual", channel=channel)
    other = can.Bus(interface="virtual", channel=channel)
    try:
        with SlcanPtyBridge(bridge_side) as bridge:
            yield bridge, other
    finally:
        other.shutdown()
        bridge_side.shutdown()


def read_until(port: serial.Serial, n_bytes: int) -> bytes:
    """Read until ``n_bytes`` came or nothing more comes within 0.3 s (bounded)."""
    out = b""
    deadline = time.monotonic() + BOUND_S
    while len(out) < n_bytes and time.monotonic() < deadline:
        chunk = port.read(n_bytes - len(out))
        if not chunk:
            break
        out += chunk
    return out


def test_replies_a_client_has_not_read_yet_are_not_flushed_by_open(bridge_and_bus) -> None:
    """python-can writes C, S8, O without reading and then reads from a thread: flushing at O
    raced with that read (pyserial: "device reports readiness to read but returned no data")."""
    bridge, _ = bridge_and_bus
    with serial.Serial(bridge.port, timeout=0.3) as port:
        port.write(b"C\rS8\r")
        time.sleep(0.2)  # the bridge has answered both; the client reads nothing yet
        port.write(b"O\r")
        time.sleep(0.2)  # ... and has handled O before the client reads
        assert read_until(port, 3) == b"\r\r\r"


def test_frames_left_by_a_client_that_died_with_the_channel_open_are_dropped(
    bridge_and_bus,
) -> None:
    bridge, bus = bridge_and_bus
    with serial.Serial(bridge.port, timeout=0.3) as first:
        first.write(b"O\r")
        assert read_until(first, 1) == b"\r"
        for k in range(3):
            bus.send(can.Message(arbitration_id=0x700 + k, data=[5], is_extended_id=False))
        deadline = time.monotonic() + BOUND_S
        while bridge.frames_out < 3 and time.monotonic() < deadline:
            time.sleep(0.01)
        assert bridge.frames_out == 3  # queued on the pty, never read: the client "dies"
    with serial.Serial(bridge.port, timeout=0.3) as second:
        second.write(b"C\r")
        assert read_until(second, 64) == b"\r"  # only the reply to C, no stale frame


def test_open_bus_returns_once_the_bridge_has_handled_the_opening_commands(
    bridge_and_bus, monkeypatch
) -> None:
    """The bridge drops what a dead client left queued when the next one sends C (a flush of
    the pty). On a loaded machine it handled C after the new client's reader had started
    (python-can writes C, S, O without reading): a flush between that reader's select() and
    read() makes the read return nothing, and pyserial raises "device reports readiness to
    read but returned no data". ``open_bus`` returns once the bridge has answered them, so no
    reader runs before the flush is over."""
    from robot.canopen.bus import open_bus

    bridge, _ = bridge_and_bus
    handle = bridge.adapter.handle

    def late(line):  # a bridge thread that a busy machine schedules late
        if line == b"C":
            time.sleep(0.3)
        return handle(line)

    monkeypatch.setattr(bridge.adapter, "handle", late)
    client = open_bus(f"slcan:{bridge.port}")
    try:
        assert bridge.adapter.is_open  # C, S, the empty command and O all handled
    finally:
        client.shutdown()
