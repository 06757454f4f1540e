"""Crash campaign over the emulated serial bus: ``ergo explore --rig dynamixel`` in a child
process drives the twin through six emulated XL-320 on a pseudo-terminal (``PtyBusServer``,
in this process, with the twin in real time and its camera as an MJPEG stream on 127.0.0.1),
and is SIGKILLed at seeded random moments, then resumed each time.

After every kill the history on disk must verify (checksums), hold episodes 0..k-1 with none
missing or duplicated, and never shrink; the emulated servos are left with torque on by the
killed process (a SIGKILL runs no handler), and the next child takes the arm over from there.
At the end an uninterrupted child completes the run, whose history is then exactly 0..N-1.
The twin runs in real time here, so unlike tests/system/test_crash.py the history is not
compared with a reference run (physics timing differs run to run); the integrity checks are
the same. Together with that file's 20 kills on the twin, the campaign has 26 kills.

Episodes are shortened through the run's config (80 Hz control, so the 40-point movement
lasts 0.5 s; 0.25 s reset; 0.2 s settle cap) so that a kill cycle takes a few seconds.
Figures are printed for docs/reliability.md.
"""

from __future__ import annotations

import contextlib
import os
import random
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from explore.rigs.episodes import EpisodeConfig
from explore.rigs.rig import RigConfig
from explore.runs.config import RunConfig
from explore.runs.layout import HISTORY_FILE, METRICS_FILE
from explore.runs.open_run import open_run
from explore.runs.record import EpisodeRecord
from explore.runs.store import RunStore, _scan

ROOT = Path(__file__).resolve().parents[2]  # the repository (tests/system/ is 2 deep)
EPISODES = 10
KILLS = 6
LAUNCH_KILLS = (1, 4)  # which kills land during start-up; the others mid-exploration
CAMPAIGN_SEED = 8
CHILD_BOUND_S = 120.0  # a bound against hangs, not an expectation


@contextlib.contextmanager
def _served(tmp: Path) -> Iterator[tuple[str, str, object]]:
    """The twin in real time behind a pty (stable link ``tmp/ttyERGO``) and its camera;
    yields (port, camera URL, emulator)."""
    from sim.dynamixel.emulator import DynamixelEmulator
    from sim.dynamixel.server import PtyBusServer
    from sim.mjpeg_server import MjpegServer, TwinFrames
    from sim.realtime import RealtimeLoop
    from sim.twin import Twin

    twin = Twin(render_size=(64, 64))
    emulator = DynamixelEmulator(twin)
    try:
        with (
            RealtimeLoop(twin),
            PtyBusServer(emulator, link=tmp / "ttyERGO") as server,
            MjpegServer(TwinFrames(twin), fps=10) as camera,
        ):
            yield server.port, camera.url, emulator
    finally:
        twin.close()


def _create_run(out: Path, port: str, camera: str) -> None:
    config = RunConfig(
        rig=RigConfig("dynamixel", "crash-bus-test",
                      # 100 ms of slack and 5 retries per bus call: the emulator thread shares
                      # two busy cores with real-time physics and the camera; at the defaults
                      # (20 ms, 2) and at 50 ms and 4, a call failed after its retries at load
                      # 13-15
                      {"port": port, "camera": camera, "latency_s": 0.1, "retries": 5}),
        seed=5,
        episodes=EPISODES,
        # Twice the control rate, for speed. The return to rest takes 0.5 s, not 0.25: with
        # 0.25 s the loads stay at the servos' limit from one episode into the next (the
        # settle reads the arm), and the load watchdog rightly stops the arm after 2 s.
        episode=EpisodeConfig(rate_hz=80.0, reset_s=0.5, settle_max_s=0.2, settle_check_s=0.1),
    )  # fmt: skip
    open_run(out, config, mode="new").close()  # the rig is built, not connected


def _on_disk(out: Path) -> int:
    """Complete episodes in ``out/history.bin``, read without modifying it; fails the test on
    a bad checksum or a missing or duplicated episode."""
    hist = out / HISTORY_FILE
    if not hist.exists():
        return 0
    data = hist.read_bytes()
    spans, _ = _scan(data)  # raises RunStoreError on real corruption
    for i, (a, b) in enumerate(spans):
        assert EpisodeRecord.from_bytes(data[a:b]).episode == i, f"record {i} out of order"
    return len(spans)


def _size(path: Path) -> int:
    try:
        return path.stat().st_size
    except FileNotFoundError:
        return -1


def _cmd(out: Path) -> list[str]:
    return [sys.executable, "-m", "explore.cli", "explore", "--out", str(out),
            "--resume-or-new", "--no-progress"]  # fmt: skip


@pytest.mark.slow
def test_sigkills_over_the_serial_bus_resume_with_a_verified_history(tmp_path):
    rng = random.Random(CAMPAIGN_SEED)
    out = tmp_path / "run"
    hist = out / HISTORY_FILE
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    kills: list[tuple[str, int, int]] = []
    t_start = time.monotonic()
    with _served(tmp_path) as (port, camera, emulator):
        _create_run(out, port, camera)
        proc: subprocess.Popen | None = None
        try:
            while len(kills) < KILLS:
                before = _on_disk(out)
                assert before < EPISODES, f"the run finished after only {len(kills)} kills"
                mode = "launch" if len(kills) in LAUNCH_KILLS else "progress"
                size0 = _size(hist)
                proc = subprocess.Popen(
                    _cmd(out), cwd=ROOT, env=env, stdout=subprocess.DEVNULL,
                    stderr=subprocess.PIPE, text=True, start_new_session=True,
                )  # fmt: skip
                deadline = time.monotonic() + CHILD_BOUND_S
                if mode == "launch":  # imports, camera and bus connect, history replay
                    time.sleep(rng.uniform(0.5, 2.5))
                else:  # mid-exploration: after this child's first append
                    while _size(hist) <= size0 and proc.poll() is None:
                        assert time.monotonic() < deadline, "child made no progress"
                        time.sleep(0.002)
                    time.sleep(rng.uniform(0.0, 1.5))
                assert proc.poll() is None, f"child ended on its own: {proc.stderr.read()[-2000:]}"
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait()
                proc = None
                after = _on_disk(out)
                assert after >= before, f"kill {len(kills)} lost episodes: {before} -> {after}"
                kills.append((mode, before, after))
            torque_left_on = all(emulator.torque_states().values())
            done = subprocess.run(
                _cmd(out), cwd=ROOT, env=env, capture_output=True, text=True,
                timeout=CHILD_BOUND_S,
            )  # fmt: skip
            assert done.returncode == 0, done.stderr[-2000:]
        finally:
            if proc is not None:
                with contextlib.suppress(ProcessLookupError):
                    os.killpg(proc.pid, signal.SIGKILL)
                proc.wait()
        assert not any(emulator.torque_states().values())  # the clean end turned torque off
    store = RunStore.open(out)  # verifies every checksum
    try:
        assert [r.episode for r in store] == list(range(EPISODES))
    finally:
        store.close()
    rows = (out / METRICS_FILE).read_text().splitlines()[1:]
    assert [int(r.split(",")[0]) for r in rows] == list(range(EPISODES))
    modes = {m: sum(k[0] == m for k in kills) for m in ("launch", "progress")}
    mid_run = sum(0 < k[1] < EPISODES for k in kills)
    print(
        f"\nbus crash campaign: {len(kills)} SIGKILLs survived ({modes}), {mid_run} with "
        f"episodes already stored, torque left on by the last kill: {torque_left_on}, "
        f"{time.monotonic() - t_start:.1f} s"
    )
    assert len(kills) == KILLS and mid_run >= KILLS - 2
