"""The CANopen stand-in's heartbeats under load: ``ergo twin serve --bus canopen`` in one
process, ``ergo explore --rig canopen --can slcan:PTY --camera URL`` in another, beside N busy
processes; every stop resumed.

    python tests/stress/can_heartbeat.py --episodes 300 --load 8
    python tests/stress/can_heartbeat.py --episodes 30 --busy 0

Printed: each stop as it comes and why (the last line of the failed run; a "no heartbeat"
stop is a heartbeat the host missed), then the episodes stored, the served drives' heartbeats
as the emulator wrote them to the pty (``ergo twin serve``'s log line: how many, dropped, how
many late, the longest gap), the load average during the run (mean, max) and the wall time.
``-- --heartbeats threads`` serves them from the server's own threads, for comparison. No
fault is injected: every late heartbeat is the emulator's or the host's lateness.
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

from explore.runs.layout import RUN_FILE

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
    ap.add_argument("serve_args", nargs="*", help="more `ergo twin serve` arguments (after --)")
    args = ap.parse_args()
    n = args.busy
    if args.load is not None:
        n = max(0, round(args.load - 2 - load_average()))  # the run itself is about 2
    tmp = Path(tempfile.mkdtemp(prefix="can-heartbeat-"))
    run = args.out or tmp / "run"
    print(f"load average before: {load_average():.2f}; {n} busy process(es); run {run}")
    serve_log = tmp / "serve.log"
    with open(serve_log, "w") as err:
        serve = subprocess.Popen(
            [*ERGO, "twin", "serve", "--bus", "canopen", *args.serve_args],
            cwd=ROOT, stdout=subprocess.PIPE, stderr=err, text=True,
        )  # fmt: skip
    samples: list[float] = []
    stop = threading.Event()

    def sample() -> None:
        while not stop.wait(SAMPLE_S):
            samples.append(load_average())

    stops: list[str] = []
    try:
        assert serve.stdout is not None
        port = serve.stdout.readline().split()[-1]
        camera = serve.stdout.readline().split()[-1]
        base = [*ERGO, "explore", "--no-progress", "--rerun", "off"]
        new = [*base, "--rig", "canopen", "--rig-id", "heartbeat", "--can", f"slcan:{port}",
               "--camera", camera, "--strategy", args.strategy,
               "--episodes", str(args.episodes), "--out", str(run)]  # fmt: skip
        resume = [*base, "--resume", str(run), "--rig-option", f"can={json.dumps('slcan:' + port)}",
                  "--rig-option", f"camera={json.dumps(camera)}"]  # fmt: skip
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
                print(f"  stopped ({time.monotonic() - t0:.0f} s): {stops[-1]}", flush=True)
                if len(stops) > args.max_resumes:
                    break
                cmd = resume if (run / RUN_FILE).exists() else new  # a first session stopped
        wall = time.monotonic() - t0
    finally:
        stop.set()
        serve.terminate()
        serve.wait(timeout=20)
    stored = _stored(run)
    samples = samples or [load_average()]
    missed = sum("no heartbeat" in line for line in stops)
    print(f"episodes stored: {stored}/{args.episodes}; stops: {len(stops)}, {missed} of them a "
          f"heartbeat the host missed; {wall:.0f} s")  # fmt: skip
    print(
        f"load average during the run: {sum(samples) / len(samples):.1f} (max {max(samples):.1f})"
    )
    for line in serve_log.read_text().splitlines():
        if "drives' heartbeats" in line or "emulated drives:" in line:
            print(f"  served: {line}")
    return 0 if stored == args.episodes and not missed else 1


def _stored(run: Path) -> int:
    from explore.runs.layout import HISTORY_FILE
    from explore.runs.store import iter_history

    return sum(1 for _ in iter_history(run)) if (run / HISTORY_FILE).exists() else 0


if __name__ == "__main__":
    os.chdir(ROOT)
    sys.path.insert(0, str(ROOT))
    sys.exit(main())
