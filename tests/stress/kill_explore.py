"""SIGKILL of ``ergo explore`` mid-run, N times, on a served bus: are the servos limp after, and
how soon? Read back over the bus by a reader of this script's own.

    python tests/stress/kill_explore.py --bus dynamixel --kills 20 --busy 4
    python tests/stress/kill_explore.py --bus canopen --kills 20 --busy 4
    python tests/stress/kill_explore.py --bus canopen --kills 5 --group   # the guardian too
    python tests/stress/kill_explore.py --bus dynamixel --kills 2 --hold  # the control

One ``ergo twin serve --bus BUS`` for all kills. Each kill: ``ergo explore --rig BUS`` on the
served pty and camera, SIGKILL once its first episode is stored plus a random 0.2-2 s (so most
kills land mid-episode), then the reader opens the pty and polls every ``POLL_S``: on
Dynamixel, Torque Enable (address 24) of servos 1..6 by READ; on CANopen the statusword 0x6041
of nodes 1..6 by SDO (the reader sends no heartbeat of its own). Limp: every servo reads
Torque Enable 0 / every drive is out of OPERATION ENABLED. ``--group`` kills explore's whole
process group, the torque-off guardian included: then only the drives' own watch of the host
(CANopen, their heartbeat consumer) can act. ``--hold`` runs explore with the rig option
``on_crash=hold``: the control, where nothing may cut torque.

Printed: one line per kill (the time from the kill to the first read showing all six limp,
or "STILL ENABLED"), then the count limp and the largest time, and the load average.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import random
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

from load import busy, load_average  # tests/stress/load.py, beside this script

ROOT = Path(__file__).resolve().parents[2]
ERGO = [sys.executable, "-m", "explore.cli"]
POLL_S = 0.1  # s between two read-backs of the six servos
GIVE_UP_S = 8.0  # a servo still enabled this long after the kill is reported enabled
FIRST_EPISODE_S = 120.0  # bound on the wait for explore's first stored episode


def read_dynamixel(port: str) -> list[bool | None]:
    """Torque Enable of servos 1..6 (None: no answer)."""
    from robot.dynamixel.bus import DynamixelBus

    bus = DynamixelBus(port, retries=2)
    bus.open()
    try:
        out: list[bool | None] = []
        for sid in range(1, 7):
            try:
                out.append(bool(bus.read(sid, 24, 1, check_alert=False)[0]))
            except Exception:
                out.append(None)
        return out
    finally:
        bus.close()


class CanReader:
    """SDO reads of the drives' statuswords on the served SLCAN pty; no heartbeat sent."""

    def __init__(self, can: str) -> None:
        import canopen

        from robot.canopen.bus import open_bus, parse_can_spec
        from robot.canopen.config import EDS_PATH

        self.network = canopen.Network(open_bus(parse_can_spec(can, None)))
        self.network.connect()
        self.nodes = []
        for nid in range(1, 7):
            node = canopen.RemoteNode(nid, canopen.import_od(str(EDS_PATH), nid))
            node.sdo.RESPONSE_TIMEOUT = 1.0
            self.network.add_node(node)
            self.nodes.append(node)

    def enabled(self) -> list[bool | None]:
        from robot.canopen.cia402 import State, decode_statusword

        out: list[bool | None] = []
        for node in self.nodes:
            try:
                out.append(decode_statusword(int(node.sdo[0x6041].raw)) is State.OPERATION_ENABLED)
            except Exception:
                out.append(None)
        return out

    def close(self) -> None:
        self.network.disconnect()


def history_has_an_episode(run: Path) -> bool:
    from explore.runs.layout import HISTORY_FILE

    path = run / HISTORY_FILE
    return path.exists() and path.stat().st_size > 0


def one_kill(args: argparse.Namespace, k: int, port: str, camera: str, tmp: Path) -> str:
    run = tmp / f"run{k}"
    bus_args = ["--port", port] if args.bus == "dynamixel" else ["--can", f"slcan:{port}"]
    cmd = [*ERGO, "explore", "--no-progress", "--rerun", "off", "--rig", args.bus,
           "--rig-id", f"kill{k}", *bus_args, "--camera", camera, "--strategy", "rpe",
           "--episodes", "1000", "--seed", str(k), "--out", str(run),
           *(["--rig-option", 'on_crash="hold"'] if args.hold else [])]  # fmt: skip
    log = (tmp / f"explore{k}.log").open("w")
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=log, stderr=subprocess.STDOUT,
                            start_new_session=True)  # fmt: skip
    deadline = time.monotonic() + FIRST_EPISODE_S
    while not history_has_an_episode(run) and proc.poll() is None:
        if time.monotonic() > deadline:
            break
        time.sleep(0.05)
    if proc.poll() is not None or not history_has_an_episode(run):
        proc.kill()
        proc.wait()
        return f"kill {k}: explore did not store an episode (rc {proc.returncode}; {log.name})"
    time.sleep(random.Random(k).uniform(0.2, 2.0))
    if args.group:
        os.killpg(proc.pid, signal.SIGKILL)
    else:
        proc.send_signal(signal.SIGKILL)
    killed = time.monotonic()
    proc.wait()
    reader = CanReader(f"slcan:{port}") if args.bus == "canopen" else None
    try:
        while True:
            states = reader.enabled() if reader is not None else read_dynamixel(port)
            waited = time.monotonic() - killed
            if not any(s is not False for s in states):
                return f"kill {k}: limp at +{waited:.2f} s"
            if waited > GIVE_UP_S:
                return f"kill {k}: STILL ENABLED at +{waited:.2f} s: {states}"
            time.sleep(POLL_S)
    finally:
        if reader is not None:
            reader.close()
        if args.group:
            time.sleep(0.5)  # the guardian died with the group: nothing left to reap


@contextlib.contextmanager
def served_and_busy(bus: str, tmp: Path, n_busy: int, warmup_s: float) -> Iterator[tuple[str, str]]:
    """``ergo twin serve --bus BUS`` (its log in ``tmp/serve.log``) beside ``n_busy`` busy
    processes, once the load average reached ``n_busy`` (at most ``warmup_s``); yields the
    served pty and camera URL; prints the emulated drives' summary at the end."""
    serve_log = (tmp / "serve.log").open("w")  # read by no one while it runs: never a full pipe
    serve = subprocess.Popen([*ERGO, "twin", "serve", "--bus", bus], cwd=ROOT,
                             stdout=subprocess.PIPE, stderr=serve_log, text=True)  # fmt: skip
    try:
        assert serve.stdout is not None
        port = serve.stdout.readline().split()[-1]
        camera = serve.stdout.readline().split()[-1]
        with busy(n_busy):
            end = time.monotonic() + warmup_s
            while load_average() < n_busy and time.monotonic() < end:
                time.sleep(1.0)
            yield port, camera
    finally:
        serve.terminate()
        serve.wait(timeout=10)
        serve_log.close()
        for line in (tmp / "serve.log").read_text().splitlines():
            if "emulated drives" in line:
                print(line)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--bus", choices=("dynamixel", "canopen"), required=True)
    ap.add_argument("--kills", type=int, default=20)
    ap.add_argument("--first", type=int, default=0, help="number of the first kill (seeds)")
    ap.add_argument("--busy", type=int, default=4, help="busy processes beside the runs")
    ap.add_argument("--group", action="store_true", help="kill the guardian too")
    ap.add_argument("--hold", action="store_true", help="the control: rig option on_crash=hold")
    ap.add_argument("--warmup", type=float, default=60.0,
                    help="longest wait, s, for the load average to reach --busy first")  # fmt: skip
    args = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="kill-explore-"))
    print(f"load before: {load_average():.1f}; {args.busy} busy; logs in {tmp}", flush=True)
    lines: list[str] = []
    loads: list[float] = []
    with served_and_busy(args.bus, tmp, args.busy, args.warmup) as (port, camera):
        for k in range(args.first, args.first + args.kills):
            line = one_kill(args, k, port, camera, tmp)
            loads.append(load_average())
            print(f"{line} (load {loads[-1]:.1f})", flush=True)
            lines.append(line)
    limp = [float(x.split("+")[1].split()[0]) for x in lines if "limp at" in x]
    print(
        f"{args.bus}{' (group)' if args.group else ''}: {len(limp)}/{len(lines)} limp, "
        f"largest time {max(limp, default=float('nan')):.2f} s; load {min(loads, default=0):.1f}"
        f"-{max(loads, default=0):.1f}"
    )
    return 0 if len(limp) == len(lines) else 1


if __name__ == "__main__":
    os.chdir(ROOT)
    sys.path.insert(0, str(ROOT))
    sys.exit(main())
