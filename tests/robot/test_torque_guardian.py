"""The torque-off guardian process: it writes the arm's current payload to the port as soon as
a signal number reaches its pipe (and when it is signalled itself), stamps when, passes the
signal number on, and ends with its pipe, writing nothing then."""

from __future__ import annotations

import os
import select
import signal
import socket
import termios
import time
import tty

import pytest

from robot.torque_guardian import EmergencyPayload, Guardian

BOUND_S = 5.0  # against hangs
QUIET_S = 0.3  # how long "nothing was written" is watched for, s


def _read(fd: int, n: int, bound_s: float = BOUND_S) -> bytes:
    got = b""
    deadline = time.monotonic() + bound_s
    while len(got) < n and time.monotonic() < deadline:
        if select.select([fd], [], [], 0.05)[0]:
            got += os.read(fd, 4096)
    return got


@pytest.fixture
def pty_pair():
    master, slave = os.openpty()
    tty.setraw(master, termios.TCSANOW)
    tty.setraw(slave, termios.TCSANOW)
    yield master, os.ttyname(slave)
    os.close(master)
    os.close(slave)


def test_a_signal_number_on_its_pipe_writes_the_current_payload_then_is_passed_on(pty_pair):
    master, path = pty_pair
    payload = EmergencyPayload(path, b"first")
    watcher, forward = socket.socketpair()
    guardian = Guardian.start(payload, forward.fileno(), rt_priority=10)
    try:
        payload.set(b"TORQUE-OFF")  # the arm refreshes it; the guardian writes the latest
        t0 = time.monotonic()
        os.write(guardian.wakeup_fd, bytes([signal.SIGINT]))
        assert _read(master, 10) == b"TORQUE-OFF"
        assert payload.sent_at is not None and payload.sent_at >= t0
        watcher.settimeout(BOUND_S)
        assert watcher.recv(16) == bytes([signal.SIGINT])  # then the watcher thread is woken
        os.write(guardian.wakeup_fd, b"\x00")  # not a stop signal: passed on, nothing written
        assert watcher.recv(16) == b"\x00"
        assert _read(master, 1, QUIET_S) == b""
        guardian.process.send_signal(signal.SIGTERM)  # signalled itself (a process group)
        assert _read(master, 10) == b"TORQUE-OFF"
        assert guardian.process.poll() is None  # and it goes on
    finally:
        guardian.stop()
        watcher.close()
        forward.close()
    assert guardian.process.returncode == 0  # ended with its pipe
    assert _read(master, 1, QUIET_S) == b""  # writing nothing then
    payload.close()
