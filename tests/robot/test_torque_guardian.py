"""The torque-off guardian process: it writes the arm's current payload to the port as soon as
a signal number reaches its pipe (and when it is signalled itself), stamps when, passes the
signal number on, and ends with its pipe: writing nothing when the arm's process ended the
block itself, the payload when that process died without it (SIGKILL), unless told to hold."""

from __future__ import annotations

import os
import select
import signal
import socket
import subprocess
import sys
import termios
import time
import tty

import pytest

from robot.torque_guardian import DEATH_WRITES, EmergencyPayload, Guardian

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


# A process that starts a guardian over the pty given, says "up", then waits to be killed.
ARM_PROCESS = """
import signal, socket, sys, time
from robot.torque_guardian import EmergencyPayload, Guardian
payload = EmergencyPayload(sys.argv[1], b"TORQUE-OFF")
watcher, forward = socket.socketpair()
guardian = Guardian.start(payload, forward.fileno(), rt_priority=10, on_death=sys.argv[2])
print("up", flush=True)
time.sleep(60)
"""


@pytest.mark.parametrize("on_death", ["limp", "hold"])
def test_the_arm_process_killed_leaves_the_guardian_to_write_the_payload(pty_pair, on_death):
    master, path = pty_pair
    arm = subprocess.Popen(
        [sys.executable, "-c", ARM_PROCESS, path, on_death], stdout=subprocess.PIPE,
        cwd=os.path.dirname(os.path.dirname(os.path.dirname(__file__))),
    )  # fmt: skip
    try:
        assert arm.stdout is not None and arm.stdout.readline().strip() == b"up"
        assert _read(master, 1, QUIET_S) == b""  # alive: nothing written
        arm.kill()  # SIGKILL: no handler, no finally of the arm's process runs
        arm.wait()
        want = b"TORQUE-OFF" * DEATH_WRITES if on_death == "limp" else b""
        if want:
            assert _read(master, len(want)) == want
        assert _read(master, 1, 3 * QUIET_S) == b""  # and nothing more
    finally:
        arm.kill()
        arm.wait()
        if arm.stdout is not None:
            arm.stdout.close()
