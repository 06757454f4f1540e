"""End to end: ``ergo twin serve --bus canopen`` in a subprocess (the twin in real time behind
an SLCAN adapter emulated on a pty), and a CanArm on ``slcan:/dev/pts/N`` in this process."""

from __future__ import annotations

import argparse
import os
import select
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from explore.rigs.clock import RealClock
from robot.canopen.arm import CanArm, config_for
from robot.canopen.scan import scan_cli

ROOT = Path(__file__).resolve().parents[3]  # the repository (tests/sim/canopen/ is 3 deep)
START_BOUND_S = 30.0  # a bound against hangs (the server imports MuJoCo), not an expectation

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def server() -> Iterator[str]:
    """Start the server; yield its pty path; stop it (SIGTERM, then SIGKILL if needed)."""
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    cmd = [sys.executable, "-m", "explore.cli", "twin", "serve", "--bus", "canopen", "--no-camera"]
    proc = subprocess.Popen(
        cmd, cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    try:
        ready, _, _ = select.select([proc.stdout], [], [], START_BOUND_S)
        line = proc.stdout.readline().strip() if ready else ""
        if not line.startswith("canopen bus (slcan) on /dev/"):
            proc.kill()
            pytest.fail(f"server did not start: {line!r} {proc.stderr.read()[-2000:]}")
        yield line.rsplit(" ", 1)[1]
        proc.terminate()
        assert proc.wait(timeout=10) == 0
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(timeout=5)


def test_arm_over_slcan_follows_and_turns_torque_off(server: str) -> None:
    # the pty rig's settings (robot/canopen/config.py PTY_SETTINGS: its heartbeat, as at 200 ms
    # a loaded CI machine stalled the server's heartbeats past 0.3 s; its SDO timeout, as
    # canopen's 0.3 s was missed at load 6-8), as ergo explore takes them on a pty
    cfg = config_for(f"slcan:{server}", pdo_timeout_s=0.05)
    target = np.array([0.3, 0.2, -0.3, 0.3, 0.2, -0.2])
    clock = RealClock()
    with CanArm(f"slcan:{server}", config=cfg) as arm:
        arm.set_torque(True)
        start = arm.read().positions
        clock.restart()
        for k in range(60):  # 1 s ramp then 0.5 s hold at 40 Hz, in real time
            arm.command(start + (target - start) * min(1.0, (k + 1) / 40))
            clock.advance(0.025)
        state = arm.read()
        assert np.abs(state.positions - target).max() < 0.05
        assert arm.torque_enabled
    # a new connection finds every drive with operation disabled
    with CanArm(f"slcan:{server}", config=cfg) as again:
        assert not again.torque_enabled


def test_scan_over_slcan(server: str, capsys: pytest.CaptureFixture[str]) -> None:
    args = argparse.Namespace(can=f"slcan:{server}", bitrate=1_000_000, ids=[1, 2, 3, 4, 5, 6])
    args.listen_s = 0.5
    assert scan_cli(args) == 0
    lines = capsys.readouterr().out.splitlines()
    assert len(lines) == 7 and all("CiA 402 drive" in line for line in lines[1:])


def test_bad_pty_is_a_clear_error() -> None:
    from robot.canopen.bus import CanBusError

    with pytest.raises(CanBusError, match="no such device /dev/pts/9999"):
        CanArm("slcan:/dev/pts/9999").connect()


@pytest.mark.parametrize(
    ("flags", "message"),
    [
        ({"overload_servo": 9}, "--overload-servo 9 is not a node id"),
        ({"drop_rate": 1.5}, "--drop-rate 1.5"),
        ({"delay_ms": -1.0}, "--delay-ms -1.0 is negative"),
    ],
)
def test_server_flag_errors(flags, message, capsys) -> None:
    import argparse

    from sim.canopen.server import serve

    args = argparse.Namespace(
        **{"drop_rate": 0.0, "delay_ms": 0.0, "overload_servo": None, **flags}
    )
    assert serve(args) == 2
    assert message in capsys.readouterr().err
