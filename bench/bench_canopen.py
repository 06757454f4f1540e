"""Control cycles per second of ``CanArm`` against the emulated drives, next to what a 1 Mbit/s
CAN bus allows for the frames of one cycle. A benchmark, not a test:

    .venv/bin/python bench/bench_canopen.py [--cycles 300] [--skip-pty]

One control cycle = ``arm.command(q)`` + ``arm.read()``: six RPDO1 (controlword + target, 6 data
bytes), one SYNC (0 bytes) and six TPDO1 (statusword + position, 6 bytes) = 13 frames. Two
transports:

- ``virtual``: python-can's in-process bus, drives in the same process (no wire at all);
- ``slcan pty``: ``ergo twin serve --bus canopen`` in a subprocess, SLCAN ASCII over a
  pseudo-terminal, python-can's ``slcan`` interface on this side (as with a CANable).

The twin runs in real time in both (``RealtimeLoop``), as in the server.
"""

from __future__ import annotations

import argparse
import os
import select
import subprocess
import sys
import time
import uuid
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "experiments"))

from script_helpers import stop_process  # noqa: E402  (experiments/script_helpers.py)

from robot.canopen.arm import CanArm, CanArmConfig  # noqa: E402

BITRATE = 1_000_000
N_NODES = 6
PDO_BYTES = 6  # RPDO1 and TPDO1 both carry 2 + 4 bytes


def frame_bits(n_bytes: int, worst_stuffing: bool = True) -> int:
    """Bits on the wire of a classic CAN frame with an 11-bit id and ``n_bytes`` of data,
    interframe space included: 47 + 8n, plus at most floor((34 + 8n - 1) / 4) stuff bits
    (Davis, Burns, Bril, Lukkien 2007, "Controller Area Network (CAN) schedulability analysis:
    refuted, revisited and revised", eq. for standard frames)."""
    bits = 47 + 8 * n_bytes
    if worst_stuffing:
        bits += (34 + 8 * n_bytes - 1) // 4
    return bits


def cycle_bound(worst_stuffing: bool = True) -> float:
    """Control cycles per second a 1 Mbit/s bus carries, frames of one cycle back to back."""
    bits = 2 * N_NODES * frame_bits(PDO_BYTES, worst_stuffing) + frame_bits(0, worst_stuffing)
    return BITRATE / bits


def run_cycles(arm: CanArm, cycles: int) -> float:
    """Cycles per second of command + read, small moves around the start pose."""
    arm.set_torque(True)
    start = arm.read().positions
    t0 = time.perf_counter()
    for k in range(cycles):
        arm.command(start + 0.05 * np.sin(2 * np.pi * k / 100))
        arm.read()
    return cycles / (time.perf_counter() - t0)


def bench_virtual(cycles: int) -> float:
    from sim.canopen.drives import EmulatedDrives
    from sim.realtime import RealtimeLoop
    from sim.twin import Twin

    twin = Twin()
    can = f"virtual:bench-{uuid.uuid4().hex[:8]}"
    with RealtimeLoop(twin), EmulatedDrives(twin, can), CanArm(can) as arm:
        return run_cycles(arm, cycles)


def bench_pty(cycles: int) -> float:
    cmd = [sys.executable, "-m", "sim.canopen.server", "--no-camera"]
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    proc = subprocess.Popen(cmd, cwd=ROOT, env=env, stdout=subprocess.PIPE, text=True)
    try:
        ready, _, _ = select.select([proc.stdout], [], [], 30.0)
        line = proc.stdout.readline().strip() if ready else ""
        if " on /dev/" not in line:
            raise RuntimeError(f"server did not start: {line!r}")
        path = line.rsplit(" ", 1)[1]
        with CanArm(f"slcan:{path}", config=CanArmConfig(pdo_timeout_s=0.05)) as arm:
            return run_cycles(arm, cycles)
    finally:
        stop_process(proc, timeout_s=10)


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--cycles", type=int, default=300, help="control cycles per transport")
    p.add_argument("--skip-pty", action="store_true", help="only the in-process virtual bus")
    args = p.parse_args()
    bound = cycle_bound()
    print(
        f"frames per cycle: {2 * N_NODES + 1} ({N_NODES} RPDO + SYNC + {N_NODES} TPDO); "
        f"1 Mbit/s bound {bound:.0f} cycles/s with worst-case bit stuffing "
        f"({cycle_bound(False):.0f} without)"
    )
    rows = [("virtual (in-process)", bench_virtual(args.cycles))]
    if not args.skip_pty:
        rows.append(("slcan on a pty", bench_pty(args.cycles)))
    print(f"{'transport':<22} {'cycles/s':>9} {'bound':>7} {'ratio':>6}")
    for name, rate in rows:
        print(f"{name:<22} {rate:9.0f} {bound:7.0f} {rate / bound:6.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
