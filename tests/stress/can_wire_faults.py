"""CANopen wire garbage and drops under ``ergo explore``: how many drives are left enabled 2 s
after explore exits? Read back over the bus by a reader of this script's own.

    python tests/stress/can_wire_faults.py --runs 50 --busy 4

One ``ergo twin serve --bus canopen``. Each run: a wire proxy (tests/wire_proxy.py) between
the served SLCAN pty and ``ergo explore --rig canopen`` (4 episodes); ``GARBAGE_AFTER_S`` into
the run, for ``FAULT_S``: even runs get random bytes both ways (a noisy line: the host's own
torque-off frames can be lost in it), odd runs lose 30 % of the SLCAN lines both ways and get
garbage toward the host. Explore stops with one line or finishes; ``AFTER_EXIT_S`` after it
exited the reader (``kill_explore.CanReader``, on the served pty, not through the proxy) reads
every drive's statusword.

Printed: one line per run (explore's exit code and last line, the drives still in OPERATION
ENABLED), then the count of runs that left a drive enabled, and the load average.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from kill_explore import ERGO, ROOT, CanReader, served_and_busy  # tests/stress/, beside this
from load import load_average

GARBAGE_AFTER_S = 7.0  # s after explore starts (its connect takes 2-4 s at load 4-8)
FAULT_S = 2.0  # how long the faults last, s
AFTER_EXIT_S = 2.0  # when the drives are read back after explore exited, s
RUN_BOUND_S = 120.0  # explore killed past this (a bound against a hang)


def one_run(k: int, device: str, camera: str, tmp: Path) -> tuple[str, int]:
    sys.path.insert(0, str(ROOT / "tests"))
    from wire_proxy import Faults, WireProxy

    run = tmp / f"run{k}"
    with WireProxy(device, framing="slcan", seed=k) as proxy:
        cmd = [*ERGO, "explore", "--no-progress", "--rerun", "off", "--rig", "canopen",
               "--rig-id", f"wire{k}", "--can", f"slcan:{proxy.port}", "--camera", camera,
               "--strategy", "rpe", "--episodes", "4", "--seed", str(k),
               "--out", str(run)]  # fmt: skip
        proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                text=True)  # fmt: skip
        try:
            out, _ = proc.communicate(timeout=GARBAGE_AFTER_S)
        except subprocess.TimeoutExpired:
            if k % 2:
                for d in (proxy.to_host, proxy.to_device):
                    d.faults = Faults(drop_rate=0.3)
                proxy.garbage(FAULT_S, "host")
            else:
                proxy.garbage(FAULT_S, "host")
                proxy.garbage(FAULT_S, "device")
            time.sleep(FAULT_S)
            proxy.clear()
            try:
                out, _ = proc.communicate(timeout=RUN_BOUND_S)
            except subprocess.TimeoutExpired:
                proc.kill()
                out, _ = proc.communicate()
        exited = time.monotonic()
    time.sleep(max(0.0, AFTER_EXIT_S - (time.monotonic() - exited)))
    reader = CanReader(f"slcan:{device}")
    try:
        states = reader.enabled()
    finally:
        reader.close()
    enabled = [i + 1 for i, s in enumerate(states) if s is not False]
    last = (out.strip().splitlines() or ["(no output)"])[-1][:160]
    return (
        f"run {k}: rc {proc.returncode}; {last!r}; enabled after {AFTER_EXIT_S:.0f} s: {enabled}",
        len(enabled),
    )


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=50)
    ap.add_argument("--first", type=int, default=0, help="number of the first run (seeds)")
    ap.add_argument("--busy", type=int, default=4)
    ap.add_argument("--warmup", type=float, default=60.0,
                    help="longest wait, s, for the load average to reach --busy first")  # fmt: skip
    args = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="can-wire-"))
    print(f"load before: {load_average():.1f}; {args.busy} busy; runs in {tmp}", flush=True)
    bad = 0
    loads: list[float] = []
    with served_and_busy("canopen", tmp, args.busy, args.warmup) as (device, camera):
        for k in range(args.first, args.first + args.runs):
            line, n_enabled = one_run(k, device, camera, tmp)
            loads.append(load_average())
            bad += n_enabled > 0
            print(f"{line} (load {loads[-1]:.1f})", flush=True)
    print(
        f"canopen wire faults: {bad}/{args.runs} run(s) left a drive enabled "
        f"{AFTER_EXIT_S:.0f} s after explore exited; load {min(loads, default=0):.1f}-"
        f"{max(loads, default=0):.1f}"
    )
    return 0 if bad == 0 else 1


if __name__ == "__main__":
    os.chdir(ROOT)
    sys.path.insert(0, str(ROOT))
    sys.exit(main())
