"""The reliability tests beside N busy processes: pass counts at a given machine load.

    python tests/stress/load.py --busy 6                  # six spinning processes beside the tests
    python tests/stress/load.py --load 8                  # as many as bring the load to about 8
    python tests/stress/load.py --busy 0 --repeat 3       # the tests alone, three times
    python tests/stress/load.py --busy 4 -- tests/system/test_signals_bus.py   # other tests

A busy process is one Python loop that never sleeps (one runnable task: +1 to the load
average). They start before the tests, run at this script's own niceness (run it all under
``nice -n 10`` on a shared machine: the busy processes then compete with the tests as the
other jobs do, and no harder with anything else), and are stopped when the tests end, also on
Ctrl-C. ``--load L`` starts ``L - 1 - (load average now)`` of them (the tests themselves are
about 1), at least 0: the load that is already there counts.

Printed, per repetition: the busy processes, the 1-minute load average sampled every 5 s
during the tests (mean and max; it lags by about a minute, so the first samples
underestimate), the counts of passed, failed, skipped and errors, the wall time, and the
failures by name, and where pytest's output was kept. The default tests are the reliability
suite of docs/reliability.md.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
import xml.etree.ElementTree as ET
from collections.abc import Iterator
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
RELIABILITY_TESTS = [
    "tests/system",
    "tests/robot",
    "tests/sim/dynamixel",
    "tests/sim/canopen",
]
SAMPLE_S = 5.0  # how often the load average is read, s
SPIN = "while True: pass"


def load_average() -> float:
    """The 1-minute load average (``/proc/loadavg``)."""
    return os.getloadavg()[0]


@contextlib.contextmanager
def busy(n: int) -> Iterator[list[int]]:
    """``n`` spinning processes for the block; their pids. Each is killed by its pid after."""
    procs = [
        subprocess.Popen([sys.executable, "-c", SPIN], stdin=subprocess.DEVNULL) for _ in range(n)
    ]
    try:
        yield [p.pid for p in procs]
    finally:
        for p in procs:
            with contextlib.suppress(ProcessLookupError):
                p.send_signal(signal.SIGKILL)
        for p in procs:
            p.wait()


def _sample(into: list[float], stop: threading.Event) -> None:
    while not stop.wait(SAMPLE_S):
        into.append(load_average())


def run_tests(
    tests: list[str], extra: list[str], log: Path
) -> tuple[dict[str, int], list[str], float]:
    """Run pytest on ``tests``, its output into ``log``; (counts, failed test ids, wall s)."""
    with tempfile.TemporaryDirectory() as tmp:
        report = Path(tmp) / "report.xml"
        cmd = [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
               f"--junitxml={report}", *extra, *tests]  # fmt: skip
        t0 = time.monotonic()
        with open(log, "w") as out:
            subprocess.run(cmd, cwd=ROOT, stdout=out, stderr=subprocess.STDOUT)
        wall = time.monotonic() - t0
        counts = {"passed": 0, "failed": 0, "skipped": 0, "errors": 0}
        failed: list[str] = []
        if not report.exists():
            return {**counts, "errors": 1}, ["pytest wrote no report"], wall
        for case in ET.parse(report).getroot().iter("testcase"):
            name = f"{case.get('classname')}::{case.get('name')}"
            tags = {child.tag for child in case}
            if "failure" in tags:
                counts["failed"] += 1
                failed.append(name)
            elif "error" in tags:
                counts["errors"] += 1
                failed.append(f"{name} (error)")
            elif "skipped" in tags:
                counts["skipped"] += 1
            else:
                counts["passed"] += 1
    return counts, failed, wall


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    group = ap.add_mutually_exclusive_group()
    group.add_argument("--busy", type=int, help="busy processes to run beside the tests")
    group.add_argument("--load", type=float, help="start enough busy processes for this load")
    ap.add_argument("--repeat", type=int, default=1, help="runs of the tests (default 1)")
    ap.add_argument("--pytest-arg", action="append", default=[], help="extra pytest argument")
    ap.add_argument("tests", nargs="*", help=f"tests (default: {' '.join(RELIABILITY_TESTS)})")
    args = ap.parse_args()
    tests = args.tests or RELIABILITY_TESTS
    before = load_average()
    n = args.busy if args.busy is not None else 0
    if args.load is not None:
        n = max(0, round(args.load - 1 - before))
    if n < 0:
        ap.error("--busy must be >= 0")
    print(f"load average before: {before:.2f}; {n} busy process(es); niceness {os.nice(0)}")
    logs = Path(tempfile.mkdtemp(prefix="stress-load-"))
    worst = 0
    with busy(n):
        for k in range(args.repeat):
            samples: list[float] = []
            stop = threading.Event()
            sampler = threading.Thread(target=_sample, args=(samples, stop), daemon=True)
            sampler.start()
            try:
                log = logs / f"run-{k + 1}.log"
                counts, failed, wall = run_tests(tests, args.pytest_arg, log)
            finally:
                stop.set()
                sampler.join()
            samples = samples or [load_average()]
            mean = sum(samples) / len(samples)
            total = sum(counts.values())
            print(
                f"run {k + 1}: busy {n}, load {mean:.1f} (max {max(samples):.1f}), "
                f"{counts['passed']}/{total} passed, {counts['failed']} failed, "
                f"{counts['errors']} errors, {counts['skipped']} skipped, {wall:.0f} s"
            )
            for name in failed:
                print(f"  failed: {name}")
            print(f"  pytest output: {log}")
            worst = max(worst, counts["failed"] + counts["errors"])
    return 1 if worst else 0


if __name__ == "__main__":
    sys.exit(main())
