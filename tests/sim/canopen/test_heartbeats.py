"""The served drives' heartbeats come from a process of their own (``sim.canopen.heartbeats``):
on time while the emulator's process runs nothing at all, written to the adapter's pty only
while the host has it open, with the drives' NMT state, and stopped as the drives stop them;
``CanArm`` over the bridge sees them as before (a stopped one is a lost node)."""

from __future__ import annotations

import itertools
import os
import threading
import time
import tty
import uuid
from collections.abc import Iterator

import can
import pytest

from robot import SafetyStop
from robot.canopen.arm import CanArm, CanArmConfig
from sim.canopen.drives import EmulatedDrives
from sim.canopen.heartbeats import BridgeRecord, HeartbeatProducer
from sim.canopen.server import SlcanPtyBridge
from sim.twin import Twin
from testkit.gil import hold_the_gil

PERIOD_S = 0.2
BOUND_S = 10.0  # against hangs
# A CanArm in the emulator's own process, over its pty: the pty rig's PDO timeout, SDO timeout
# and consumer time (robot.canopen.config), and positions allowed to age 3 s (the emulator's
# threads share this process's GIL: late TPDOs are not what these tests are about).
IN_PROCESS = {
    "pdo_timeout_s": 0.05,
    "sdo_timeout_s": 2.0,
    "consumer_ms": 2000,
    "max_position_age_s": 3.0,
}


def heartbeat_lines(fd: int) -> list[bytes]:
    data = b""
    while True:
        try:
            chunk = os.read(fd, 4096)
        except BlockingIOError:
            break
        if not chunk:
            break
        data += chunk
    return [line for line in data.split(b"\r") if line]


def hung_up(fd: int) -> bool:
    """Whether the pty behind the client descriptor ``fd`` was closed (its master gone: a
    write fails with EIO, a read finds its end), within ``BOUND_S`` (the kernel hangs the
    client side up right after the close)."""
    deadline = time.monotonic() + BOUND_S
    while time.monotonic() < deadline:
        try:
            os.write(fd, b"V\r")
            if os.read(fd, 16) == b"":
                return True
        except BlockingIOError:
            pass
        except OSError:
            return True
        time.sleep(0.01)
    return False


@pytest.fixture
def pty() -> Iterator[tuple[int, int]]:
    master, slave = os.openpty()
    tty.setraw(master)
    tty.setraw(slave)
    os.set_blocking(slave, False)
    yield master, slave
    os.close(master)
    os.close(slave)


def test_heartbeats_stay_on_time_while_the_emulators_process_runs_nothing(pty):
    master, slave = pty
    ticks: list[float] = []
    stop = threading.Event()

    def tick() -> None:  # what python-can's periodic task was: a thread of this process
        while not stop.wait(0.01):
            ticks.append(time.monotonic())

    with HeartbeatProducer() as producer:
        producer.set_port(master)
        producer.set_open(True)
        for node in range(1, 7):
            producer.task(node, b"\x7f", PERIOD_S)
        ticker = threading.Thread(target=tick, daemon=True)
        ticker.start()
        time.sleep(2 * PERIOD_S)
        held = hold_the_gil(1.0)
        time.sleep(2 * PERIOD_S)
        stop.set()
        ticker.join()
        stats = producer.stats()
    thread_gap = max(b - a for a, b in itertools.pairwise(ticks))
    # this process's threads stopped for longer than a host waits for a heartbeat
    assert held > 1.5 * PERIOD_S and thread_gap > 1.5 * PERIOD_S
    assert set(stats) == set(range(1, 7))
    for node, (written, dropped, late, longest) in stats.items():
        assert written >= (4 * PERIOD_S + held) / PERIOD_S - 1, (node, written)
        assert dropped == 0 and late == 0, (node, stats[node])
        assert longest < 1.5 * PERIOD_S, (node, longest)
    lines = heartbeat_lines(slave)
    assert {line[:4] for line in lines} == {b"t%03X" % (0x700 + n) for n in range(1, 7)}
    assert all(line[4:] == b"17F" for line in lines)  # one byte: pre-operational


def test_only_while_the_adapter_is_open_and_with_the_state_and_period_given(pty):
    master, slave = pty
    with HeartbeatProducer() as producer:
        producer.set_port(master)
        task = producer.task(3, b"\x7f", 0.05)
        time.sleep(0.3)
        assert heartbeat_lines(slave) == []  # closed: nothing
        producer.set_open(True)
        time.sleep(0.3)
        task.update(b"\x05")  # NMT start: operational
        time.sleep(0.3)
        task.stop()
        time.sleep(0.1)
        lines = heartbeat_lines(slave)
        time.sleep(0.3)
        assert heartbeat_lines(slave) == []  # stopped
    assert b"t70317F" in lines and b"t703105" in lines
    assert lines.index(b"t70317F") < lines.index(b"t703105")


def test_unplugging_the_adapter_closes_the_producers_copy_of_the_pty():
    channel = f"hb-{uuid.uuid4().hex[:8]}"
    bus = can.Bus(interface="virtual", channel=channel)
    producer = HeartbeatProducer()
    try:
        with SlcanPtyBridge(bus, heartbeats=producer) as bridge:
            fd = os.open(bridge.path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
            try:
                bridge.unplug()
                assert hung_up(fd)  # the pty is gone: no copy keeps it open
            finally:
                os.close(fd)
    finally:
        producer.stop()
        bus.shutdown()


def test_a_can_arm_over_the_bridge_hears_them_and_a_stopped_one_is_a_lost_node():
    channel = f"hb-{uuid.uuid4().hex[:8]}"
    producer = HeartbeatProducer()
    drives = EmulatedDrives(
        Twin(), f"virtual:{channel}", sync_step_s=0.025, heartbeats=producer.task
    )
    bus = can.Bus(interface="virtual", channel=channel)
    try:
        with drives, SlcanPtyBridge(bus, heartbeats=producer) as bridge:
            config = CanArmConfig(heartbeat_ms=200, **IN_PROCESS)
            with CanArm(f"slcan:{bridge.path}", config=config) as arm:  # NMT start: heard
                arm.set_torque(True)
                drives.stop_heartbeat(3)
                with pytest.raises(SafetyStop, match=r"node 3 \(m3\) lost: no heartbeat"):
                    deadline = time.monotonic() + BOUND_S
                    while time.monotonic() < deadline:
                        arm.command(arm.read().positions)
                        time.sleep(0.02)
        assert producer.stats()[1][0] > 0
    finally:
        producer.stop()
        bus.shutdown()


def test_the_bridges_record_of_heartbeats_from_the_serving_process():
    """``--heartbeats threads``: the bridge keeps the record (late gaps, the longest as
    written and as produced, the wait in between); other frames are not counted."""
    record = BridgeRecord(lambda node: 0.05)
    stamp = time.time()
    record.record(0x701, stamp)
    record.record(0x181, stamp)  # a TPDO: not a heartbeat
    time.sleep(0.1)  # two periods: late
    record.record(0x701, stamp + 0.09)
    record.reset()  # a new client
    time.sleep(0.1)
    record.record(0x701, time.time())
    assert record.written == 3 and record.late == 1
    assert 0.09 < record.longest < 0.5 and record.longest_produced == pytest.approx(0.09)
    assert "3 written to the host, 1 late" in record.summary()


def test_no_heartbeat_is_dropped_while_the_bridge_writes_to_the_same_pty(pty):
    """The pty's descriptor is non-blocking and shared with the bridge: a write that finds the
    tty's write lock held by the bridge's (EAGAIN, the buffer not full) is tried again, not
    counted dropped; the host, reading everything, misses no heartbeat."""
    master, slave = pty
    os.set_blocking(master, False)
    stop = threading.Event()
    got = bytearray()

    def bridge() -> None:  # TPDO-like lines as fast as the tty takes them
        while not stop.is_set():
            try:
                os.write(master, b"t1858000000000000FF00\r")
            except BlockingIOError:
                time.sleep(0.0005)

    def host() -> None:  # reads everything, at once
        while not stop.is_set():
            try:
                got.extend(os.read(slave, 65536))
            except BlockingIOError:
                time.sleep(0.0005)

    threads = [threading.Thread(target=f, daemon=True) for f in (bridge, host)]
    with HeartbeatProducer() as producer:
        producer.set_port(master)
        producer.set_open(True)
        for node in range(1, 7):
            producer.task(node, b"\x05", PERIOD_S / 2)
        for t in threads:
            t.start()
        time.sleep(20 * PERIOD_S)
        stats = producer.stats()
        stop.set()
        for t in threads:
            t.join()
    for node, (written, dropped, _late, _longest) in stats.items():
        assert dropped == 0 and written >= 30, (node, stats[node])
    heard = {n: bytes(got).count(b"t%03X105\r" % (0x700 + n)) for n in range(1, 7)}
    assert min(heard.values()) >= 30, heard
