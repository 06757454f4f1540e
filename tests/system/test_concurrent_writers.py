"""Two ``ergo explore`` processes on one run at once (``--resume RUN`` or ``--out RUN
--resume-or-new``, both started together): one writes, the other is refused in one line naming
the writer's pid, and the history never holds a duplicated episode. A writer killed with
SIGKILL leaves its lock behind; the next writer takes it over and says so.

``ERGO_WRITER_TRIES`` sets the number of tries (default 4; docs/reliability.md reports 20).
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from explore.runs.layout import HISTORY_FILE
from explore.runs.repair import survey

ROOT = Path(__file__).resolve().parents[2]
TRIES = int(os.environ.get("ERGO_WRITER_TRIES", "4"))
BOUND_S = 300.0  # against hangs, not an expectation


def _explore(*args: str) -> subprocess.Popen:
    cmd = [sys.executable, "-m", "explore.cli", "explore", "--no-progress", "--rerun", "off",
           "--rig-option", "render_size=[64,64]", *args]  # fmt: skip
    return subprocess.Popen(cmd, cwd=ROOT, text=True, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE)  # fmt: skip


def _errors(err: str) -> list[str]:
    return [line for line in err.splitlines() if line.startswith("ergo: error:")]


@pytest.mark.slow
def test_two_writers_at_once_never_duplicate_an_episode(tmp_path):
    run = tmp_path / "run"
    duplicated = refused = 0
    for i in range(TRIES):
        episodes = str(2 * (i + 1))
        if i % 2 == 0:
            args = ("--out", str(run), "--resume-or-new", "--episodes", episodes)
        else:
            args = ("--resume", str(run), "--episodes", episodes)
        procs = [_explore(*args), _explore(*args)]
        ends = [(p.pid, p.wait(timeout=BOUND_S), p.stderr.read()) for p in procs]
        codes = sorted(rc for _, rc, _ in ends)
        assert codes in ([0, 0], [0, 2]), ends
        for pid, rc, err in ends:
            if rc == 2:
                refused += 1
                other = next(p for p, _, _ in ends if p != pid)
                (line,) = _errors(err)
                assert "is being written by another process" in line, line
                assert f"(pid {other} on " in line, (line, other)
        s = survey(run)
        episodes_seen = [p.episode for p in s.good]
        duplicated += len(episodes_seen) - len(set(episodes_seen))
        assert not s.needs_salvage and s.prefix == int(episodes), (i, episodes_seen)
    print(f"\n{TRIES} tries of two writers: {refused} refused, {duplicated} duplicated episodes")
    assert duplicated == 0


@pytest.mark.slow
def test_the_lock_of_a_killed_writer_is_taken_over_and_said_so(tmp_path):
    run = tmp_path / "run"
    proc = _explore("--out", str(run), "--episodes", "50")
    hist, deadline = run / HISTORY_FILE, time.monotonic() + BOUND_S
    while not (hist.exists() and hist.stat().st_size > 0):
        assert time.monotonic() < deadline and proc.poll() is None, proc.stderr.read()
        time.sleep(0.02)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    again = _explore("--resume", str(run), "--episodes", "2")
    assert again.wait(timeout=BOUND_S) == 0
    err = again.stderr.read()
    assert f"took over the lock of a writer that ended without releasing it (pid {proc.pid} " in err
