"""A controller killed with SIGKILL leaves the servos limp, on both buses: a child process drives
the emulated arm (Dynamixel on a pty, CANopen drives behind an SLCAN pty, both in this
process) inside ``torque_off_on_signals``, and is killed mid-command.

- The child alone killed: its torque-off guardian process outlives it and writes the
  torque-off (``robot.torque_guardian``), on both buses.
- The child and its guardian killed (the whole process group): on CANopen the drives' own
  watch of the host's heartbeat (0x1016, 0x6007: ``sim.canopen.guard``) disables them after
  the consumer time.

Deadlines are bounds (the tests hold at load 8 on 2 cores), the order of events is what is
asserted: torque on before the kill, off after it.
"""

from __future__ import annotations

import contextlib
import os
import select
import signal
import subprocess
import sys
import textwrap
import time
import uuid
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
START_BOUND_S = 60.0  # the child's start and connect
LIMP_BOUND_S = 10.0  # from the kill to every servo limp
CONSUMER_MS = 1000  # the drives' consumer time of the host's heartbeat in the CANopen child

CHILD = textwrap.dedent(
    f"""
    import sys, time
    import numpy as np
    from robot.signals import torque_off_on_signals
    kind, port = sys.argv[1], sys.argv[2]
    if kind == "serial":
        from robot.dynamixel.arm import DynamixelArm
        arm = DynamixelArm(port, latency_s=0.02)
    else:
        from robot.canopen.arm import CanArm, CanArmConfig
        arm = CanArm(f"slcan:{{port}}", config=CanArmConfig(
            heartbeat_ms=500, sdo_timeout_s=2.0, pdo_timeout_s=0.05, consumer_ms={CONSUMER_MS}))
    with arm, torque_off_on_signals(arm):
        arm.set_torque(True)
        q0 = arm.read().positions
        print("on", flush=True)
        for k in range(100000):
            arm.command(q0 + 0.05 * np.sin(0.1 * k))
            time.sleep(0.025)
    """
)


@contextlib.contextmanager
def dynamixel_pty() -> Iterator[tuple[str, Callable[[], bool]]]:
    """A pty of six emulated XL-320 and whether all six have torque off."""
    from sim.dynamixel.emulator import DynamixelEmulator
    from sim.dynamixel.server import PtyBusServer

    emulator = DynamixelEmulator(None)
    with PtyBusServer(emulator) as server:
        yield server.path, lambda: not any(emulator.torque_states().values())


@contextlib.contextmanager
def canopen_pty() -> Iterator[tuple[str, Callable[[], bool]]]:
    """An SLCAN pty of six emulated drives and whether none is in OPERATION ENABLED."""
    import can

    from robot.canopen.cia402 import State
    from sim.canopen.drives import EmulatedDrives
    from sim.canopen.server import SlcanPtyBridge
    from sim.twin import Twin

    channel = f"kill-{uuid.uuid4().hex[:8]}"
    twin = Twin()
    drives = EmulatedDrives(twin, f"virtual:{channel}", sync_step_s=0.025)
    bridge_bus = can.Bus(interface="virtual", channel=channel)
    try:
        with drives, SlcanPtyBridge(bridge_bus) as bridge:
            drives.host_backlog = bridge.backlog
            yield bridge.path, lambda: State.OPERATION_ENABLED not in drives.states().values()
    finally:
        bridge_bus.shutdown()
        twin.close()


def kill_mid_command(kind: str, port: str, limp: Callable[[], bool], group: bool) -> float:
    """Start the child on ``port``, SIGKILL it (and its group) once torque is on; returns the
    seconds from the kill to every servo limp."""
    proc = subprocess.Popen(
        [sys.executable, "-c", CHILD, kind, port], cwd=ROOT, text=True,
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, start_new_session=True,
    )  # fmt: skip
    try:
        assert select.select([proc.stdout], [], [], START_BOUND_S)[0], "child silent"
        line = proc.stdout.readline().strip()
        assert line == "on", line or proc.stderr.read()[-2000:]
        time.sleep(0.3)  # commanding
        assert not limp()
        killed = time.monotonic()
        os.killpg(proc.pid, signal.SIGKILL) if group else proc.kill()
        proc.wait()
        while not limp() and time.monotonic() - killed < LIMP_BOUND_S:
            time.sleep(0.01)
        waited = time.monotonic() - killed
        assert limp(), f"{kind}: still enabled {waited:.1f} s after the kill"
        return waited
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()


@pytest.mark.slow
def test_a_killed_controller_leaves_the_xl320s_limp():
    with dynamixel_pty() as (port, limp):
        print(f"dynamixel: limp {kill_mid_command('serial', port, limp, group=False):.2f} s after")


@pytest.mark.slow
@pytest.mark.parametrize("group", [False, True], ids=["guardian", "drives-alone"])
def test_a_killed_controller_leaves_the_drives_limp(group):
    with canopen_pty() as (port, limp):
        waited = kill_mid_command("can", port, limp, group=group)
    print(f"canopen ({'group' if group else 'child'} killed): limp {waited:.2f} s after")
    if group:  # the drives' own watch: not before the consumer time
        assert waited >= CONSUMER_MS / 1000 * 0.9
