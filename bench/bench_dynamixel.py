"""Control cycles per second over the Dynamixel bus, next to what the wire allows.

One cycle = SYNC_WRITE of six goal positions + SYNC_READ of six present positions and speeds
(what ``DynamixelArm.command`` + ``read`` do on most ticks). By default the bus is the twin's
emulator on a pseudo-terminal, started as a subprocess (``ergo twin serve --bus dynamixel``);
``--port`` benchmarks a real bus instead.

The bound is the bytes of one cycle at the baud rate (10 bits a byte) plus the servos' return
delays: what a perfect adapter and host would reach. A pty has no baud rate, so the ratio says
how much of a 1 Mbps wire's budget the host side (Python, the emulator, the OS) uses up.

    .venv/bin/python bench/bench_dynamixel.py [--seconds 3] [--port /dev/ttyUSB0]
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import time

from robot.dynamixel import protocol as proto
from robot.dynamixel.bus import STATUS_OVERHEAD, DynamixelBus
from robot.dynamixel.control_table import XL320

IDS = [1, 2, 3, 4, 5, 6]


def cycle_bytes(ids: list[int]) -> int:
    """Bytes on the wire for one cycle (requests + every status packet)."""
    goal = XL320.reg("goal")
    address, length = XL320.block(["position", "velocity"])
    write = proto.sync_write(goal.address, goal.size, {i: goal.encode(512) for i in ids})
    read = proto.sync_read(address, length, ids)
    return len(write.encode()) + len(read.encode()) + len(ids) * (STATUS_OVERHEAD + length)


def run(bus: DynamixelBus, seconds: float) -> tuple[int, float]:
    """Cycles done in about ``seconds``, and the time they took."""
    goal = XL320.reg("goal")
    address, length = XL320.block(["position", "velocity"])
    n = 0
    start = time.perf_counter()
    while time.perf_counter() - start < seconds:
        step = 512 + (n % 20)
        bus.sync_write(goal.address, goal.size, {i: goal.encode(step) for i in IDS})
        bus.sync_read(address, length, IDS)
        n += 1
    return n, time.perf_counter() - start


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=3.0, help="how long to run, s")
    parser.add_argument("--port", help="a real bus instead of the emulator")
    parser.add_argument("--baud", type=int, default=1_000_000)
    args = parser.parse_args(argv)

    server = None
    port = args.port
    if port is None:
        cmd = [sys.executable, "-m", "explore.cli", "twin", "serve", "--bus", "dynamixel"]
        server = subprocess.Popen([*cmd, "--no-camera"], stdout=subprocess.PIPE, text=True)
        line = server.stdout.readline().strip()  # "dynamixel bus on /dev/pts/N"
        if not line.startswith("dynamixel bus on "):
            server.terminate()
            print(f"bench: the emulator did not start: {line!r}", file=sys.stderr)
            return 1
        port = line.split()[-1]
    try:
        with DynamixelBus(port, args.baud, latency_s=0.05) as bus:
            reg = XL320.reg("return_delay")
            delays = bus.sync_read(reg.address, reg.size, IDS)
            if any(d != b"\x00" for d in delays.values()):  # EEPROM: only with torque off
                for i in IDS:
                    bus.write(i, reg.address, b"\x00")
            bus.return_delay_s = 0.0
            run(bus, 0.3)  # warm up
            bus.counters.reset()
            n, elapsed = run(bus, args.seconds)
            counters = bus.counters.as_dict()
    finally:
        if server is not None:
            server.terminate()
            server.wait(timeout=10)
    n_bytes = cycle_bytes(IDS)
    bound = 1.0 / (n_bytes * 10 / args.baud)
    rate = n / elapsed
    where = "pty emulator" if args.port is None else args.port
    print(f"bus: {where}, {len(IDS)} servos, return delay 0")
    print(f"measured: {n} cycles in {elapsed:.2f} s = {rate:.0f} cycles/s ({1e3 / rate:.2f} ms)")
    print(f"wire bound: {n_bytes} bytes/cycle at {args.baud} baud = {bound:.0f} cycles/s")
    print(f"ratio measured/bound: {rate / bound:.2f}")
    print(f"counters: {counters}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
