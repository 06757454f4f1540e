"""Crash campaign: SIGKILL ``ergo explore`` at seeded random moments, resume each time, and check
the history at the end is exactly the uninterrupted run's.

Kill moments (seeded, see ``_plan``), counted in the run's own progress so that any machine
gets its kills before the run ends: about 1 in 4 kills land a random 0.3-1.5 s after launch, or
at the child's first new append if that comes sooner (interpreter start, imports, run-folder
creation, replay of the history, twin restore); the others land after the child's first or
second new append plus a random share of the fastest episode's measured duration (inside
episodes, during the next append's write/fsync). A few of those kill the instant
``history.bin`` grows, which is during or just after an append's write, before or during its
fsync. A kill thus lets 1-3 episodes pass (more only when this test is descheduled while the
child appends: on a busy machine 70 episodes were done after 17 kills), so 20 kills fit in
the 120 episodes at any speed.

Between kills the history on disk is checked without touching it: every complete record has a
valid checksum, episodes are 0..k-1 (none missing, none duplicated) and k never goes down.

Figures of one run on 2 shared cores: 20 kills, about 25 s (episodes of 22 ms).
"""

from __future__ import annotations

import contextlib
import math
import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from explore.cli import main
from explore.runs.layout import HISTORY_FILE, METRICS_FILE
from explore.runs.record import EpisodeRecord
from explore.runs.store import RunStore, _scan

EPISODES = 120  # room for 20 kills of up to 6 episodes each
SEED = 11
MIN_KILLS = 20
CAMPAIGN_SEED = 20240611
# 64 x 64 renders: the recorded image is 64 x 64 anyway, and software rendering at 240 x 240
# costs about 0.2 s per episode on this machine (measured), which would stretch the campaign.
RIG_OPTION = "render_size=[64,64]"


def _cmd(out: Path) -> list[str]:
    return [
        sys.executable, "-m", "explore.cli", "explore", "--episodes", str(EPISODES),
        "--seed", str(SEED), "--out", str(out), "--resume-or-new", "--no-progress",
        "--rig-option", RIG_OPTION,
    ]  # fmt: skip


def _on_disk(out: Path) -> tuple[int, int]:
    """(complete episodes, torn bytes) of ``out/history.bin``, read without modifying it.

    Fails the test if the history is corrupt or an episode is missing or duplicated.
    """
    hist = out / HISTORY_FILE
    if not hist.exists():
        return 0, 0
    data = hist.read_bytes()
    spans, good_end = _scan(data)  # raises RunStoreError on real corruption
    for i, (a, b) in enumerate(spans):
        rec = EpisodeRecord.from_bytes(data[a:b])
        assert rec.episode == i, f"record {i} holds episode {rec.episode}"
    return len(spans), len(data) - good_end


def _plan(rng: random.Random) -> tuple[str, float, int]:
    """Where the next kill lands: (mode, delay, appends). ``launch``: ``delay`` s after launch
    (or at the first new append, if sooner); ``append``: the instant of the first new append;
    ``progress``: ``appends`` new appends (1 or 2), then ``delay`` episodes' durations (0-1)."""
    r = rng.random()
    if r < 0.25:
        return "launch", rng.uniform(0.3, 1.5), 0
    if r < 0.4:
        return "append", 0.0, 1
    return "progress", rng.uniform(0.0, 1.0), rng.randint(1, 2)


def _wait_appends(
    hist: Path, size: int, proc: subprocess.Popen, n: int, until: float
) -> list[float]:
    """Wait until ``hist`` has grown ``n`` times past ``size`` (bytes), the child exited or
    ``until`` (monotonic s) passed; the monotonic times of the growths seen."""
    seen = []
    while len(seen) < n and proc.poll() is None and time.monotonic() < until:
        now = _size(hist)
        if now > size:
            seen.append(time.monotonic())
            size = now
        time.sleep(0.001)
    return seen


def _kill_group(proc: subprocess.Popen) -> None:
    with contextlib.suppress(ProcessLookupError):
        os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()


def _size(path: Path) -> int:
    try:
        return path.stat().st_size
    except FileNotFoundError:
        return -1


@pytest.mark.slow
def test_twenty_random_sigkills_resume_to_the_uninterrupted_history(tmp_path):
    rng = random.Random(CAMPAIGN_SEED)
    out = tmp_path / "killed"
    hist = out / HISTORY_FILE
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    kills: list[tuple[str, int, int]] = []  # (mode, episodes before, episodes after)
    torn_seen = 0
    # the fastest episode seen, s (the first after a launch can be much slower: warm-up), so
    # that a progress kill lands before the next append
    episode_s = math.inf
    proc: subprocess.Popen | None = None
    t_start = time.monotonic()
    try:
        while len(kills) < MIN_KILLS:
            before, _ = _on_disk(out)
            assert before < EPISODES, (
                f"the run finished after only {len(kills)} kills: lower the kill delays"
            )
            mode, delay, appends = _plan(rng)
            size0 = _size(hist)
            proc = subprocess.Popen(
                _cmd(out), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                start_new_session=True, env=env,
            )  # fmt: skip
            if mode == "launch":
                _wait_appends(hist, size0, proc, 1, time.monotonic() + delay)
            else:
                seen = _wait_appends(hist, size0, proc, appends, time.monotonic() + 120)
                if len(seen) == 2:  # one episode, measured on this machine now
                    episode_s = min(episode_s, seen[1] - seen[0])
                time.sleep(delay * (episode_s if episode_s < math.inf else 0.0))
            if proc.poll() is not None:
                assert proc.returncode == 0, f"child failed on its own: {proc.returncode}"
                break  # the run completed before this kill
            _kill_group(proc)
            proc = None
            after, torn = _on_disk(out)
            torn_seen += torn > 0
            assert after >= before, f"kill {len(kills)} lost episodes: {before} -> {after}"
            kills.append((mode, before, after))
        # finish the run without interruption
        done = subprocess.run(_cmd(out), capture_output=True, text=True, timeout=300, env=env)
        assert done.returncode == 0, done.stderr[-2000:]
    finally:
        if proc is not None:
            _kill_group(proc)
    campaign_s = time.monotonic() - t_start

    # the reference: the same run, never interrupted
    ref = tmp_path / "ref"
    assert main([*_cmd(ref)[3:]]) == 0

    killed = RunStore.open(out)  # verifies every checksum
    reference = RunStore.open(ref)
    try:
        assert [r.episode for r in killed] == list(range(EPISODES))
        assert len(reference) == EPISODES
        assert all(a.equals(b) for a, b in zip(killed, reference, strict=True))
    finally:
        killed.close()
        reference.close()
    rows = (out / METRICS_FILE).read_text().splitlines()[1:]
    assert [int(r.split(",")[0]) for r in rows] == list(range(EPISODES))

    modes = {m: sum(k[0] == m for k in kills) for m in ("launch", "progress", "append")}
    in_run = sum(0 < k[1] < EPISODES for k in kills)
    print(
        f"\ncrash campaign: {len(kills)} SIGKILLs survived ({modes}), {in_run} with episodes "
        f"already stored, torn tails seen {torn_seen}, {campaign_s:.1f} s, episode "
        f"{episode_s * 1000:.0f} ms"
    )
    assert len(kills) >= MIN_KILLS
    assert modes["progress"] + modes["append"] >= MIN_KILLS // 2  # most kills mid-exploration


def test_a_kill_while_run_json_is_written_does_not_block_the_folder(tmp_path, capsys):
    out = tmp_path / "r"
    out.mkdir()
    (out / "run.json.tmp").write_text('{"app": "ergo-ex')  # what the kill leaves behind
    code = main(
        ["explore", "--episodes", "1", "--out", str(out), "--resume-or-new", "--no-progress",
         "--rig-option", RIG_OPTION]
    )  # fmt: skip
    assert code == 0, capsys.readouterr().err


def test_python_dash_m_gives_one_line_errors_too(tmp_path):
    done = subprocess.run(
        [sys.executable, "-m", "explore.cli", "explore", "--episodes", "0"],
        capture_output=True, text=True, timeout=60, cwd=tmp_path,
    )  # fmt: skip
    assert done.returncode == 2 and len(done.stderr.strip().splitlines()) == 1, done.stderr
