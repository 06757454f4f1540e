"""A hardware-in-the-loop run over a pseudo-terminal with default settings, as a user makes
it: ``ergo twin serve --bus dynamixel`` in one process, ``ergo explore --rig dynamixel --port
PTY --camera URL`` in another, beside N busy processes; every stop resumed.

    python tests/stress/hil_pty.py --episodes 30 --busy 4
    python tests/stress/hil_pty.py --episodes 300 --load 6 --strategy rpe

Printed: the episodes stored, the resumes needed and why (the last line of each failed run),
the bus's fault counters summed over the sessions (``RUN/faults.json``: calls, retries,
timeouts, CRC errors, late replies set aside), the load average during the run (mean, max)
and the wall time. No fault is injected: every retry, timeout or late reply counted is the
host's or the emulator's lateness, and CRC errors should be 0.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

from load import busy, load_average  # tests/stress/load.py, beside this script

from explore.runs.layout import FAULTS_FILE, HISTORY_FILE, RUN_FILE

ROOT = Path(__file__).resolve().parents[2]
ERGO = [sys.executable, "-m", "explore.cli"]
SAMPLE_S = 5.0  # how often the load average is read, s


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    group = ap.add_mutually_exclusive_group()
    group.add_argument("--busy", type=int, default=0, help="busy processes beside the run")
    group.add_argument("--load", type=float, help="start enough busy processes for this load")
    ap.add_argument("--episodes", type=int, default=30)
    ap.add_argument("--strategy", default="rpe")
    ap.add_argument("--max-resumes", type=int, default=50)
    ap.add_argument("--out", type=Path, help="run folder (default: a temporary one)")
    ap.add_argument("explore_args", nargs="*", help="more `ergo explore` arguments (after --)")
    args = ap.parse_args()
    n = args.busy
    if args.load is not None:
        n = max(0, round(args.load - 2 - load_average()))  # the run itself is about 2
    run = args.out or Path(tempfile.mkdtemp(prefix="hil-pty-")) / "run"
    print(f"load average before: {load_average():.2f}; {n} busy process(es); run {run}")
    serve = subprocess.Popen([*ERGO, "twin", "serve", "--bus", "dynamixel"], cwd=ROOT,
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)  # fmt: skip
    samples: list[float] = []
    stop = threading.Event()

    def sample() -> None:
        while not stop.wait(SAMPLE_S):
            samples.append(load_average())

    try:
        port = serve.stdout.readline().split()[-1]
        camera = serve.stdout.readline().split()[-1]
        base = [*ERGO, "explore", "--no-progress", "--rerun", "off"]
        new = [*base, "--rig", "dynamixel", "--rig-id", "hil", "--port", port, "--camera", camera,
               "--strategy", args.strategy, "--episodes", str(args.episodes),
               "--out", str(run), *args.explore_args]  # fmt: skip
        resume = [*base, "--resume", str(run), "--rig-option", f"port={json.dumps(port)}",
                  "--rig-option", f"camera={json.dumps(camera)}"]  # fmt: skip
        stops: list[str] = []
        threading.Thread(target=sample, daemon=True).start()
        t0 = time.monotonic()
        with busy(n):
            cmd = new
            while True:
                done = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
                if done.returncode == 0:
                    break
                lines = (done.stderr or done.stdout).strip().splitlines() or ["(no output)"]
                stops.append(f"rc {done.returncode}: {lines[-1]}")
                if len(stops) > args.max_resumes or not (run / RUN_FILE).exists():
                    break
                cmd = resume
        wall = time.monotonic() - t0
    finally:
        stop.set()
        serve.terminate()
        serve.wait(timeout=10)
    stored = len(list(_episodes(run)))
    faults = json.loads((run / FAULTS_FILE).read_text()) if (run / FAULTS_FILE).exists() else {}
    totals = faults.get("totals", {})
    samples = samples or [load_average()]
    print(f"episodes stored: {stored}/{args.episodes}; resumes: {len(stops)}; {wall:.0f} s")
    print(
        f"load average during the run: {sum(samples) / len(samples):.1f} (max {max(samples):.1f})"
    )
    keys = ("bus_calls", "bus_retries", "bus_timeouts", "bus_crc_errors", "bus_late_replies")
    print("bus: " + ", ".join(f"{k[4:]} {totals.get(k, 0):g}" for k in keys))
    for line in stops:
        print(f"  stopped: {line}")
    ok = stored == args.episodes and not totals.get("bus_crc_errors")
    return 0 if ok else 1


def _episodes(run: Path):
    from explore.runs.store import iter_history

    return iter_history(run) if (run / HISTORY_FILE).exists() else iter(())


if __name__ == "__main__":
    os.chdir(ROOT)
    sys.path.insert(0, str(ROOT))
    sys.exit(main())
