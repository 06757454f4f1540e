"""Garbage from an SLCAN adapter (noise on the serial line, a wrong baud rate, not an SLCAN
device at all): ``robot.canopen.bus.tolerant_slcan_bus`` drops each garbled line and counts
it, python-can's reader thread never dies of it, and a port of nothing but garbage is a
one-line error at connect (docs/reliability.md)."""

from __future__ import annotations

import contextlib
import logging
import os
import random
import termios
import threading
import time
import tty
from collections.abc import Iterator

import pytest

from robot.canopen.arm import CanArm, CanArmConfig
from robot.canopen.bus import open_bus
from robot.errors import BusError

NO_THREAD_TRACEBACK = pytest.mark.filterwarnings(
    "error::pytest.PytestUnhandledThreadExceptionWarning"
)


@pytest.fixture
def pty() -> Iterator[tuple[int, str]]:
    """(master fd, slave path) of a raw pseudo-terminal: the test plays the adapter."""
    master, slave = os.openpty()
    tty.setraw(master, termios.TCSANOW)
    tty.setraw(slave, termios.TCSANOW)
    try:
        yield master, os.ttyname(slave)
    finally:
        os.close(master)
        os.close(slave)


@contextlib.contextmanager
def noise_on(master: int, seed: int) -> Iterator[None]:
    """Random bytes written to the adapter's side of the pty every 5 ms while in the block."""
    stop = threading.Event()

    def noise() -> None:
        rng = random.Random(seed)
        while not stop.is_set():
            with contextlib.suppress(BlockingIOError):
                os.write(master, rng.randbytes(64))
            time.sleep(0.005)

    os.set_blocking(master, False)  # never blocks once nobody reads
    thread = threading.Thread(target=noise, daemon=True)
    thread.start()
    try:
        yield
    finally:
        stop.set()
        thread.join()


def test_garbled_lines_are_dropped_and_counted_and_good_frames_still_come(pty) -> None:
    master, path = pty
    bus = open_bus(f"slcan:{path}")
    try:
        lines = [
            b"t1852AABB\r",
            b"\xff\xfe\x80garbage\r",  # not ASCII (python-can: UnicodeDecodeError)
            b"tZZZ1AA\r",  # a bad hex id
            b"t18\r",  # cut short
            b"t1858AABB\r",  # fewer data bytes than its DLC
            b"t7051" + b"05\r",  # a heartbeat: state 5
        ]
        os.write(master, b"".join(lines))
        got = []
        deadline = time.monotonic() + 5.0
        while len(got) < 2 and time.monotonic() < deadline:
            msg = bus.recv(0.1)
            if msg is not None:
                got.append((msg.arbitration_id, bytes(msg.data)))
        assert got == [(0x185, b"\xaa\xbb"), (0x705, b"\x05")]
        assert bus.garbled_lines == 4
    finally:
        bus.shutdown()


@NO_THREAD_TRACEBACK
def test_a_port_sending_only_garbage_fails_the_connect_in_one_line(pty, caplog) -> None:
    master, path = pty
    with noise_on(master, seed=0):
        arm = CanArm(f"slcan:{path}", config=CanArmConfig(sdo_timeout_s=0.2))
        with pytest.raises(BusError) as info:
            arm.connect()
    message = str(info.value)
    assert "\n" not in message
    assert "does not answer SDO 0x1000" in message and "garbled line(s)" in message, message
    assert not arm.is_connected
    # nor a second line from the canopen library ("Transfer aborted by client ...")
    assert not [r for r in caplog.records if r.levelno >= logging.WARNING], caplog.text


@NO_THREAD_TRACEBACK
def test_a_scan_of_a_port_sending_only_garbage_names_the_garbled_lines(pty, capsys) -> None:
    import argparse

    from robot.canopen.scan import scan_cli

    master, path = pty
    with noise_on(master, seed=1):
        args = argparse.Namespace(can=f"slcan:{path}", bitrate=None, ids=[1, 2], listen_s=0.3)
        rc = scan_cli(args)
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 1 and len(err) == 1, err
    assert "no CANopen node answered" in err[0] and "garbled line(s)" in err[0], err
