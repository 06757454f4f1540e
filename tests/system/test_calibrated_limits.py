"""A joint calibration applied end to end: ``ergo explore --rig dynamixel --rig-id lim`` in a
child process drives the twin through six emulated XL-320 on a pseudo-terminal (the served
twin of ``ergo twin serve --bus dynamixel``, in this process so that the servos' goal
registers can be watched), with a ``joints.json`` for ``lim`` that allows +-0.10 rad on every
joint. Random motor parameters (RPE) ask for far more; the servos must never receive a goal
outside +-0.10 rad (to half a position unit: goals are whole units). Then the calibration
changes and a resume is refused in one line naming the file and the override.

Was (issue 27): no rig read joints.json; the same run commanded up to 2.50 rad.
"""

from __future__ import annotations

import contextlib
import json
import os
import subprocess
import sys
import threading
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from calibration import store
from calibration.joints import JointCalibration
from explore.rigs.episodes import EpisodeConfig
from explore.rigs.rig import RigConfig
from explore.runs.config import RunConfig
from explore.runs.layout import HISTORY_FILE, RUN_FILE
from explore.runs.open_run import open_run
from robot.dynamixel.control_table import XL320
from robot.spec import ergo_jr_spec

LIMIT = 0.10  # rad, every joint
HALF_UNIT = XL320.rad_per_step / 2  # goals are whole position units (0.0026 rad)
EPISODES = 3
CHILD_BOUND_S = 180.0  # a bound against hangs, not an expectation


@contextlib.contextmanager
def served(tmp: Path) -> Iterator[tuple[str, str, list[tuple[int, int]]]]:
    """The twin in real time behind a pty and its camera; yields (port, camera URL, the goal
    registers written, as (servo id, raw goal) in order)."""
    from sim.dynamixel.emulator import DynamixelEmulator
    from sim.dynamixel.server import PtyBusServer
    from sim.mjpeg_server import MjpegServer, TwinFrames
    from sim.realtime import RealtimeLoop
    from sim.twin import Twin

    twin = Twin(render_size=(64, 64))
    emulator = DynamixelEmulator(twin)
    goals: list[tuple[int, int]] = []
    lock = threading.Lock()
    apply_goal = emulator._apply_goal

    def watched(servo) -> None:  # every goal a servo accepts, as the servo holds it
        with lock:
            goals.append((servo.id, servo.peek("goal")))
        apply_goal(servo)

    emulator._apply_goal = watched
    try:
        with (
            RealtimeLoop(twin),
            PtyBusServer(emulator, link=tmp / "ttyERGO") as server,
            MjpegServer(TwinFrames(twin), fps=10) as camera,
        ):
            yield server.port, camera.url, goals
    finally:
        twin.close()


def test_a_run_on_a_calibrated_rig_never_sends_a_goal_outside_the_calibrated_limits(tmp_path):
    spec = ergo_jr_spec()
    n = spec.n
    limits = JointCalibration(
        tuple(spec.names), np.zeros(n), np.ones(n), np.full(n, -LIMIT), np.full(n, LIMIT)
    )
    path = store.save("joints", "lim", limits.to_dict())  # ERGO_CALIBRATION_DIR: tests/conftest.py
    run = tmp_path / "run"
    with served(tmp_path) as (port, camera, goals):
        # the run's config with short episodes (80 Hz, 0.5 s back to rest), then the CLI
        options = {"port": port, "camera": camera, "latency_s": 0.1, "retries": 5}
        config = RunConfig(
            rig=RigConfig("dynamixel", "lim", options), seed=3, episodes=EPISODES,
            episode=EpisodeConfig(rate_hz=80.0, reset_s=0.5, settle_max_s=0.2),
        )  # fmt: skip
        open_run(run, config, mode="new").close()
        cmd = [sys.executable, "-m", "explore.cli", "explore", "--resume", str(run),
               "--no-progress", "--rerun", "off"]  # fmt: skip
        env = {**os.environ, "PYTHONUNBUFFERED": "1"}
        done = subprocess.run(cmd, capture_output=True, text=True, timeout=CHILD_BOUND_S, env=env)
        assert done.returncode == 0, done.stderr
        assert f"{EPISODES} episodes" in done.stdout
        sent = list(goals)
    assert len(sent) > 6 * 40 * EPISODES  # every tick of every movement reached the servos
    q = XL320.steps_to_rad(np.array([g for _, g in sent]))  # directions +1, offsets 0
    assert np.abs(q).max() <= LIMIT + HALF_UNIT, np.abs(q).max()
    assert np.abs(q).max() >= LIMIT - HALF_UNIT  # the commands went for more and were clamped
    recorded = json.loads((run / RUN_FILE).read_text())["inputs"]
    assert [(e["kind"], e["path"]) for e in recorded] == [("joints", str(path.resolve()))]

    # recalibrated since: the resume is refused in one line, the run left as it was
    store.save("joints", "lim", JointCalibration(
        tuple(spec.names), np.zeros(n), np.ones(n), np.full(n, -0.2), np.full(n, 0.2)
    ).to_dict())  # fmt: skip
    before = (run / RUN_FILE).read_bytes(), (run / HISTORY_FILE).read_bytes()
    more = [*cmd, "--episodes", str(EPISODES + 1)]
    done = subprocess.run(more, capture_output=True, text=True, timeout=CHILD_BOUND_S, env=env)
    err = done.stderr.strip()
    assert done.returncode == 2 and len(err.splitlines()) == 1, err
    assert "joints.json changed" in err and "--allow-changed-inputs" in err
    assert ((run / RUN_FILE).read_bytes(), (run / HISTORY_FILE).read_bytes()) == before
