"""SIGINT and SIGTERM turn torque off within 100 ms, measured on ``ergo explore`` on the twin.

The child is the real CLI with two probes patched in (no behaviour change): ``SimArm._set_torque``
records ``time.monotonic()`` (system-wide on Linux, so comparable across processes) the first
time torque goes off, and ``Explorer.step`` touches a file after each stored episode, so the
parent signals only once the exploration loop runs. The parent signals at a seeded random
moment inside the loop and computes the latency.

Every try must turn torque off within 100 ms (the issue's safety bound) and before the
process exits. A Python signal handler alone runs only between bytecodes of the main thread,
after the C call in progress (a 240 x 240 MuJoCo render takes about 0.2 s here), which gave
a median of 74 ms and a max of 115 ms; ``torque_off_on_signals`` now also cuts torque from a
watcher thread woken by ``signal.set_wakeup_fd``, which those C calls do not hold up. The
figures are printed (docs/reliability.md); the bus rigs are in tests/system/test_signals_bus.py.
"""

from __future__ import annotations

import contextlib
import os
import random
import signal
import statistics
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

CHILD = textwrap.dedent(
    """
    import os, sys, time
    from pathlib import Path
    stamp, ready = Path(sys.argv[1]), Path(sys.argv[2])
    from sim.arm import SimArm
    _orig = SimArm._set_torque
    def _set_torque(self, enabled):
        _orig(self, enabled)
        if not enabled and not stamp.exists():
            tmp = stamp.with_suffix(".tmp")
            tmp.write_text(repr(time.monotonic()))
            os.replace(tmp, stamp)
    SimArm._set_torque = _set_torque
    from explore.runs.explorer import Explorer
    _step = Explorer.step
    def step(self, k):
        row = _step(self, k)
        ready.touch()
        return row
    Explorer.step = step
    from explore.cli import main
    sys.exit(main(sys.argv[3:]))
    """
)

DEADLINE_MS = 100.0


def _one(tmp: Path, sig: int, delay: float) -> tuple[float, int, float]:
    """Signal one exploring child; returns (latency ms, exit code, exit time - stamp ms)."""
    tmp.mkdir()
    stamp, ready = tmp / "stamp", tmp / "ready"
    cmd = [sys.executable, "-c", CHILD, str(stamp), str(ready), "explore", "--episodes", "1000",
           "--out", str(tmp / "run"), "--no-progress"]  # fmt: skip
    proc = subprocess.Popen(
        cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True
    )
    try:
        deadline = time.monotonic() + 120
        while not ready.exists():
            assert proc.poll() is None, f"child exited early: {proc.returncode}"
            assert time.monotonic() < deadline, "child never started exploring"
            time.sleep(0.005)
        time.sleep(delay)
        t0 = time.monotonic()
        os.kill(proc.pid, sig)
        code = proc.wait(timeout=30)
        t_exit = time.monotonic()
        assert stamp.exists(), "torque never went off"
        t1 = float(stamp.read_text())
        return (t1 - t0) * 1000, code, (t_exit - t1) * 1000
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()


@pytest.mark.slow
def test_sigint_and_sigterm_turn_torque_off_within_100_ms(tmp_path):
    rng = random.Random(7)
    results: list[tuple[str, float, int]] = []
    for i, sig in enumerate([signal.SIGINT, signal.SIGTERM] * 3):
        lat, code, after = _one(tmp_path / f"t{i}", sig, rng.uniform(0.0, 0.5))
        results.append((signal.Signals(sig).name, lat, code))
        assert lat >= 0 and after >= 0  # torque off happened after the signal, before the exit
        assert code == (130 if sig == signal.SIGINT else 128 + signal.SIGTERM), code
    lats = [r[1] for r in results]
    print(
        f"\ntorque-off latency ms: {[f'{n} {v:.1f}' for n, v, _ in results]}; "
        f"median {statistics.median(lats):.1f}, max {max(lats):.1f}"
    )
    assert max(lats) < DEADLINE_MS, results
