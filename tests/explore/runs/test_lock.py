"""The writer's lock of a run folder: a second writer is refused in one line naming the first's
pid, a clean release leaves nothing to take over, and the lock of a writer that died (SIGKILL)
is taken over and said so."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from explore.campaigns.trial import CampaignError, Trial, run_trial
from explore.runs.config import RunConfig
from explore.runs.lock import LOCK_FILE, RunLockedError, holder_of, is_being_written, run_lock
from explore.runs.open_run import open_run

ROOT = Path(__file__).resolve().parents[3]
HOLD = textwrap.dedent(
    """
    import sys, time
    from explore.runs.lock import run_lock
    with run_lock(sys.argv[1]):
        print("held", flush=True)
        time.sleep(60)
    """
)


def _holder(run: Path) -> subprocess.Popen:
    """A process that takes the run's lock and sleeps; returns once it holds it."""
    proc = subprocess.Popen([sys.executable, "-c", HOLD, str(run)], cwd=ROOT, text=True,
                            stdout=subprocess.PIPE)  # fmt: skip
    assert proc.stdout.readline().strip() == "held"
    return proc


def test_a_second_writer_in_this_process_is_refused_and_a_clean_release_leaves_nothing(tmp_path):
    with run_lock(tmp_path) as first:
        assert first.took_over is None
        assert holder_of(tmp_path)["pid"] == os.getpid()
        with pytest.raises(RunLockedError) as info, run_lock(tmp_path):
            pass
        message = str(info.value)
        assert "\n" not in message and f"pid {os.getpid()} on " in message
    assert holder_of(tmp_path) is None
    assert (tmp_path / LOCK_FILE).read_bytes().strip() == b""  # released cleanly (blanked)
    with run_lock(tmp_path) as again:
        assert again.took_over is None


def test_a_writer_in_another_process_is_named_and_its_lock_taken_over_once_it_is_killed(tmp_path):
    proc = _holder(tmp_path)
    try:
        with pytest.raises(RunLockedError, match=f"pid {proc.pid} on "), run_lock(tmp_path):
            pass
        with pytest.raises(RunLockedError, match=f"pid {proc.pid} on "):
            open_run(tmp_path / ".", RunConfig(episodes=1))
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait()
    with run_lock(tmp_path) as lock:  # the kernel dropped the dead writer's flock
        assert lock.took_over is not None and lock.took_over["pid"] == proc.pid
        assert f"pid {proc.pid}" in lock.describe_takeover()
        assert "ended without releasing" in lock.describe_takeover()
    info = json.loads((tmp_path / LOCK_FILE).read_bytes().strip() or b"{}")
    assert info == {}  # and this writer released it cleanly


def test_every_writer_holds_the_lock_campaign_trials_and_open_run(tmp_path):
    run = tmp_path / "run"
    with open_run(run, RunConfig(episodes=1)) as opened:
        assert holder_of(run)["pid"] == os.getpid()
        assert opened.created and opened.lock is not None
        with pytest.raises(RunLockedError, match="being written by another process"):
            open_run(run, mode="resume")
        with pytest.raises(CampaignError, match=f"pid {os.getpid()}"):
            run_trial(Trial.of(str(run), "rpe", 0, 1))
    assert holder_of(run) is None
    with open_run(run, mode="resume") as again:  # released on close
        assert not again.created and again.lock.took_over is None


LOOK = textwrap.dedent(
    """
    import sys, time
    from explore.runs.lock import holder_of
    print("looking", flush=True)
    end = time.monotonic() + 30
    while time.monotonic() < end:
        holder_of(sys.argv[1])
    """
)


def test_a_reader_looking_never_blocks_nor_refuses_a_writer(tmp_path):
    """``holder_of`` (``ergo runs check``, ``ergo export``) holds the lock shared for a few
    microseconds: a writer arriving then waits for it instead of refusing itself."""
    with run_lock(tmp_path):
        pass  # the lock file exists: the reader's looks take the shared lock
    proc = subprocess.Popen([sys.executable, "-c", LOOK, str(tmp_path)], cwd=ROOT, text=True,
                            stdout=subprocess.PIPE)  # fmt: skip
    try:
        assert proc.stdout.readline().strip() == "looking"
        for _ in range(300):
            with run_lock(tmp_path):
                assert is_being_written(tmp_path)
            assert not is_being_written(tmp_path)
    finally:
        proc.kill()
        proc.wait()


def test_a_writer_refused_at_the_lock_leaves_the_new_run_of_the_holder_alone(tmp_path, monkeypatch):
    """Two ``auto`` writers that both saw no folder: the one refused at the lock must not
    discard the run the other has just made (history still empty). The race, made certain:
    the other writer makes its run and takes the lock between our look and our lock."""
    import explore.runs.open_run as open_run_module
    from explore.runs.store import RunStore

    run = tmp_path / "run"
    real_lock = open_run_module.run_lock
    other = {}

    def lock_taken_meanwhile(path):
        other["lock"] = real_lock(path)
        other["lock"].__enter__()  # the other writer holds it and makes its run
        other["store"] = RunStore.create(path, RunConfig(episodes=2).to_dict())
        return real_lock(path)  # ours: refused at once

    monkeypatch.setattr(open_run_module, "run_lock", lock_taken_meanwhile)
    with pytest.raises(RunLockedError, match="is being written by another process"):
        open_run(run, RunConfig(episodes=2), mode="auto")
    assert RunStore.is_run(run)  # the holder's run.json is still there
    other["store"].close()
    other["lock"].__exit__(None, None, None)
