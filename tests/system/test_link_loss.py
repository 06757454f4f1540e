"""A lost link to the servos: the serial adapter unplugged (the emulator's pty closed) during a
run, then plugged back (a new pty behind the same stable link, as ``/dev/serial/by-id/...``).

The run is the real ``Explorer`` on a rig made of ``DynamixelArm`` on the pty (the emulator on
the twin, served by ``PtyBusServer`` in a thread), the twin's camera and the twin's clock (so
episodes run as fast as the CPU allows). Expected:

- unplugged then back within the recovery policy's attempts: the arm reopens the port by
  name, reads the positions back, re-enables torque holding them, and the run goes on with
  no episode lost; the counters say one link lost, one reconnection;
- unplugged for good: after the bounded attempts, a one-line ``SafetyStop``; the run stops
  with its completed episodes stored, and resumes from its folder once the adapter is back;
- an arm given an open connection (``connection=``) cannot reopen it: it stops at once.

Nothing here asserts on durations; waits are bounded only against hangs.
"""

from __future__ import annotations

import json
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest

from explore.rigs.ball import TwinSensor
from explore.rigs.clock import TwinClock
from explore.rigs.rig import Rig, RigConfig
from explore.runs.config import RunConfig
from explore.runs.layout import FAULTS_FILE
from explore.runs.open_run import open_run
from explore.runs.store import RunStore
from robot.arm import RecoveryPolicy
from robot.dynamixel.arm import DynamixelArm
from robot.errors import SafetyStop
from sim.camera import SimCamera
from sim.dynamixel.emulator import DynamixelEmulator, EmulatedSerial
from sim.dynamixel.server import PtyBusServer
from sim.twin import Twin

LATENCY_S = 0.05  # slack per exchange: the emulator thread shares two busy cores (at 20 ms a
# ping failed its 3 tries once, with the full suite and a soak running)
SEED = 3


@contextmanager
def served(tmp: Path) -> Iterator[tuple[Twin, DynamixelEmulator, PtyBusServer]]:
    """The twin and its six emulated servos on a pty reachable at ``tmp/ttyERGO``."""
    twin = Twin(render_size=(64, 64))
    emulator = DynamixelEmulator(twin)
    try:
        with PtyBusServer(emulator, link=tmp / "ttyERGO") as server:
            yield twin, emulator, server
    finally:
        twin.close()


def _rig(twin: Twin, port: str, recovery: RecoveryPolicy | None = None) -> Rig:
    arm = DynamixelArm(port, latency_s=LATENCY_S, recovery=recovery)
    camera = SimCamera(twin)
    return Rig(arm=arm, camera=camera, clock=TwinClock(twin), config=RigConfig(name="sim"),
               sensor=TwinSensor(twin, camera))  # fmt: skip


def _history(path: Path) -> list[int]:
    store = RunStore.open(path)  # verifies every checksum
    try:
        return [r.episode for r in store]
    finally:
        store.close()


def test_an_unplugged_adapter_is_reopened_by_name_and_the_run_goes_on(tmp_path):
    with served(tmp_path) as (twin, emulator, server):
        rig = _rig(twin, server.port)
        run = open_run(tmp_path / "run", RunConfig(seed=SEED, episodes=4), rig=rig)
        replugged = threading.Event()
        torque_after: list[bool] = []

        def on_episode(p) -> None:
            if p.episode == 1:  # during episode 2: pull the adapter, plug it back 0.3 s later
                server.unplug()
                threading.Timer(0.3, lambda: (server.replug(), replugged.set())).start()
            if p.episode == 3:  # after the recovery: torque back on at every servo
                torque_after.append(all(emulator.torque_states().values()))

        with run:
            run.explore(on_episode=on_episode)
        counts = rig.arm.fault_counts()
        assert replugged.is_set() and server.unplugs == 1 and torque_after == [True]
        assert counts["links_lost"] == 1 and counts["reconnects"] == 1, counts
        assert counts["stops_after_link_loss"] == 0 and counts["recovery_s"] > 0
        assert _history(tmp_path / "run") == [0, 1, 2, 3]
        assert not any(emulator.torque_states().values())  # the run's end turned it off


def test_an_adapter_that_stays_unplugged_stops_the_run_which_resumes_once_it_is_back(tmp_path):
    fast = RecoveryPolicy(attempts=3, first_delay_s=0.05, max_delay_s=0.1)
    with served(tmp_path) as (twin, emulator, server):

        def on_episode(p) -> None:
            if p.episode == 2:
                server.unplug()  # and it stays out

        rig = _rig(twin, server.port, fast)
        run = open_run(tmp_path / "run", RunConfig(seed=SEED, episodes=5), rig=rig)
        with run, pytest.raises(SafetyStop) as info:
            run.explore(on_episode=on_episode)
        message = str(info.value)
        assert "\n" not in message and "link lost" in message and "not back after 3" in message
        assert "can be resumed" in message
        assert rig.arm.fault_counts()["stops_after_link_loss"] == 1
        assert not rig.arm.is_connected
        assert [r.episode for r in run.store] == [0, 1]  # completed episodes kept, none torn

        server.replug()  # the adapter is back: resume the run from its folder
        rig = _rig(twin, server.port, fast)
        with open_run(tmp_path / "run", mode="resume", rig=rig) as run:
            run.explore()
        assert _history(tmp_path / "run") == [0, 1, 2, 3, 4]
        assert not any(emulator.torque_states().values())
        faults = json.loads((tmp_path / "run" / FAULTS_FILE).read_text())  # both sessions
        assert faults["sessions"] == 2 and faults["totals"]["stops_after_link_loss"] == 1


class _Unpluggable(EmulatedSerial):
    """An in-process connection whose reads fail once ``gone`` is set."""

    gone = False

    def read(self, size: int = 1) -> bytes:
        if self.gone:
            raise OSError(5, "Input/output error")
        return super().read(size)


def test_an_arm_given_an_open_connection_cannot_reconnect_and_stops_at_once():
    link = _Unpluggable(DynamixelEmulator(None))
    arm = DynamixelArm("emulated", connection=link, latency_s=0.002)
    with arm:
        arm.set_torque(True)
        arm.command(np.full(6, 0.05))
        link.gone = True
        with pytest.raises(SafetyStop, match="cannot reconnect by itself") as info:
            arm.read()
        assert "\n" not in str(info.value)
    counts = arm.fault_counts()
    assert counts["links_lost"] == 1 and counts["reconnect_attempts"] == 0
