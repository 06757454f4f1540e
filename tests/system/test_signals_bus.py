"""SIGINT and SIGTERM cut torque within 100 ms on the bus rigs: the Dynamixel serial bus and the
CANopen bus (SLCAN adapter), each emulated on a pseudo-terminal in this process, driven by a
child process through ``DynamixelArm`` / ``CanArm`` inside ``torque_off_on_signals``.

The latency is measured where it matters: from ``os.kill`` in this process to the moment the
emulated servo/drive applies the torque-off (``EmulatedServo.torque_off_at``,
``EmulatedDrive.disabled_at``; both ``time.monotonic``, system-wide on Linux). The child's
main thread spends most of each 25 ms control tick in a 600 x 600 matrix product (a long C
call that releases the GIL, like a render or a network forward pass): a plain Python signal
handler would wait for it to return; the watcher thread of ``torque_off_on_signals`` does not.

The emulated servos and drives stand for hardware, which applies a torque-off within
microseconds of the last byte whatever the host's load; their threads (the pty server; the
SLCAN bridge and the drives' CAN reader) are run at a real-time priority where the system
allows it, so that on this shared machine the figure measures the host's path (signal,
watcher thread, bus write) rather than the emulator waiting for a CPU. The host's watcher
thread asks for a real-time priority itself (``robot.signals.WATCHER_RT_PRIORITY``).

One child serves several samples: after each signal it reports, waits for "again" on stdin and
enables torque again. The bound is the issue's safety requirement (< 100 ms on every rig),
asserted on every sample; the figures are printed for docs/reliability.md.
"""

from __future__ import annotations

import contextlib
import os
import random
import select
import signal
import subprocess
import sys
import textwrap
import threading
import time
import uuid
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]  # the repository (tests/system/ is 2 deep)
DEADLINE_MS = 100.0  # the bound
SAMPLES = 8  # per rig, SIGINT and SIGTERM alternating
BOUND_S = 30.0  # a bound against hangs (child start, connect), not an expectation

CHILD = textwrap.dedent(
    """
    import sys, time
    import numpy as np
    from robot.signals import torque_off_on_signals
    kind, port = sys.argv[1], sys.argv[2]
    if kind == "serial":
        from robot.dynamixel.arm import DynamixelArm
        arm = DynamixelArm(port, latency_s=0.02)
    else:
        from robot.canopen.arm import CanArm, CanArmConfig
        arm = CanArm(f"slcan:{port}", config=CanArmConfig(heartbeat_ms=500, pdo_timeout_s=0.05))
    work = np.random.default_rng(0).standard_normal((600, 600))
    with arm:
        while True:
            try:
                with torque_off_on_signals(arm):
                    arm.set_torque(True)
                    q0 = arm.read().positions
                    print("on", flush=True)
                    deadline, k = time.monotonic(), 0
                    while True:
                        k += 1
                        arm.command(q0 + 0.05 * np.sin(0.1 * k))
                        arm.read()
                        work @ work  # a long C call, GIL released (BLAS)
                        deadline += 0.025
                        time.sleep(max(0.0, deadline - time.monotonic()))
            except (KeyboardInterrupt, SystemExit) as exc:
                print("stopped", type(exc).__name__, flush=True)
            if sys.stdin.readline().strip() != "again":
                break
    """
)


def _readline(proc: subprocess.Popen, bound_s: float = BOUND_S) -> str:
    ready, _, _ = select.select([proc.stdout], [], [], bound_s)
    assert ready, "child silent"
    line = proc.stdout.readline()
    assert line, f"child ended: {proc.wait(timeout=5)} {proc.stderr.read()[-2000:]}"
    return line.strip()


def _campaign(port: str, kind: str, off_at: Callable[[], float | None]) -> list[float]:
    """Run the child on ``port``; returns the latencies, ms. ``off_at``: when the emulated
    arm's torque last went off (monotonic s), or None."""
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}
    proc = subprocess.Popen(
        [sys.executable, "-c", CHILD, kind, port], cwd=ROOT, env=env, text=True,
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
        start_new_session=True,
    )  # fmt: skip
    rng = random.Random(5)
    lats: list[float] = []
    try:
        for i in range(SAMPLES):
            assert _readline(proc) == "on"
            time.sleep(rng.uniform(0.05, 0.3))  # lands anywhere in the control tick
            sig = signal.SIGINT if i % 2 == 0 else signal.SIGTERM
            t0 = time.monotonic()
            os.kill(proc.pid, sig)
            deadline = t0 + 5.0
            while (off_at() or 0.0) < t0:
                assert time.monotonic() < deadline, f"torque never went off ({kind}, sample {i})"
                time.sleep(0.0005)
            lats.append((off_at() - t0) * 1000)
            expected = "KeyboardInterrupt" if sig == signal.SIGINT else "SystemExit"
            assert _readline(proc) == f"stopped {expected}"
            proc.stdin.write("again\n" if i < SAMPLES - 1 else "quit\n")
            proc.stdin.flush()
        assert proc.wait(timeout=BOUND_S) == 0, proc.stderr.read()[-2000:]
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
    return lats


# SCHED_FIFO priority of the emulator threads standing in for hardware (above the host's
# watcher at 10, so that neither waits for the other; any real-time value would do).
HARDWARE_RT_PRIORITY = 20


def _as_hardware(threads: list) -> None:
    """Run these emulator threads at a real-time priority where allowed (else unchanged)."""
    for t in threads:
        if isinstance(t, threading.Thread) and t.native_id is not None:
            with contextlib.suppress(OSError, AttributeError):
                os.sched_setscheduler(
                    t.native_id, os.SCHED_FIFO, os.sched_param(HARDWARE_RT_PRIORITY)
                )


def _report(kind: str, lats: list[float]) -> None:
    lats_s = ", ".join(f"{v:.1f}" for v in lats)
    print(
        f"\n{kind}: torque-off latency ms over {len(lats)} signals: {lats_s}; max {max(lats):.1f}"
    )
    assert len(lats) == SAMPLES
    assert max(lats) < DEADLINE_MS, (kind, lats)


@contextlib.contextmanager
def _serial_bus() -> Iterator[tuple[str, Callable[[], float | None]]]:
    from sim.dynamixel.emulator import DynamixelEmulator
    from sim.dynamixel.server import PtyBusServer

    emulator = DynamixelEmulator(None)  # ideal servos: the latency is the host's

    def off_at() -> float | None:
        stamps = [s.torque_off_at for s in emulator.servos.values()]
        return None if None in stamps else min(stamps)  # the first servo told

    with PtyBusServer(emulator) as server:
        _as_hardware([server._thread])
        yield server.path, off_at


@contextlib.contextmanager
def _can_bus() -> Iterator[tuple[str, Callable[[], float | None]]]:
    import can

    from sim.canopen.drives import EmulatedDrives
    from sim.canopen.server import SlcanPtyBridge
    from sim.twin import Twin

    channel = f"sig-{uuid.uuid4().hex[:8]}"
    twin = Twin()
    # the twin steps one control period per SYNC: no real-time loop competing for the CPU
    drives = EmulatedDrives(twin, f"virtual:{channel}", sync_step_s=0.025)
    bridge_bus = can.Bus(interface="virtual", channel=channel)

    def off_at() -> float | None:
        stamps = [d.disabled_at for d in drives.drives]
        return None if None in stamps else min(stamps)

    try:
        with drives, SlcanPtyBridge(bridge_bus) as bridge:
            _as_hardware([*bridge._threads, *drives.network.notifier._readers])
            yield bridge.path, off_at
    finally:
        bridge_bus.shutdown()
        twin.close()


@pytest.mark.slow
def test_sigint_and_sigterm_cut_torque_within_100_ms_over_the_serial_bus():
    with _serial_bus() as (port, off_at):
        _report("dynamixel serial (pty)", _campaign(port, "serial", off_at))


@pytest.mark.slow
def test_sigint_and_sigterm_cut_torque_within_100_ms_over_the_can_bus():
    with _can_bus() as (port, off_at):
        _report("canopen slcan (pty)", _campaign(port, "can", off_at))
