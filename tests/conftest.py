"""Shared fixtures and the hypothesis profiles. Rendering is headless (EGL) unless a display is
set.

The ``fuzz`` profile runs the decoders' fuzz properties for long (the byte-stream decoders of
Protocol 2.0 and SLCAN; a few hundred examples each in the suite)::

    pytest --hypothesis-profile fuzz tests/robot/dynamixel/test_protocol_fuzz.py \
        tests/sim/canopen/test_slcan_fuzz.py          # FUZZ_EXAMPLES=200000 for longer
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path

if "MUJOCO_GL" not in os.environ and not os.environ.get("DISPLAY"):
    os.environ["MUJOCO_GL"] = "egl"

import pytest
from hypothesis import HealthCheck, settings

from explore.runs.layout import HISTORY_FILE
from sim.twin import Twin

if os.environ.get("ERGO_TEST_NUDGE_ULP") == "1":  # the twin nudged: tests/nudge_twin.py
    import runpy

    runpy.run_path(str(Path(__file__).parent / "nudge_site" / "sitecustomize.py"))

# 20,000 examples per property by default (a choice: a few minutes on one core).
settings.register_profile(
    "fuzz",
    max_examples=int(os.environ.get("FUZZ_EXAMPLES", "20000")),
    deadline=None,
    database=None,
    suppress_health_check=list(HealthCheck),
)


@pytest.fixture(autouse=True)
def _own_calibration_dir(tmp_path_factory: pytest.TempPathFactory, monkeypatch) -> Path:
    """Every test (and the commands it starts) finds calibration files in an empty folder of
    its own, never the developer's (~/.config/ergo-explore/calibration): physical rigs read
    their joint and arena calibrations by rig id."""
    folder = tmp_path_factory.mktemp("calibration")
    monkeypatch.setenv("ERGO_CALIBRATION_DIR", str(folder))
    return folder


@pytest.fixture(autouse=True)
def _ordinary_scheduling() -> Iterator[None]:
    """No test leaves the suite's own process at another scheduling policy: every later test,
    and every process it starts (bus emulators, served rigs, ``ergo`` commands), would inherit
    it. (SVT-AV1 run as root once left it at SCHED_FIFO 99 after the export tests:
    explore/export/video.py.) The policy is put back and the test fails."""
    before = (os.sched_getscheduler(0), os.sched_getparam(0).sched_priority)
    yield
    after = (os.sched_getscheduler(0), os.sched_getparam(0).sched_priority)
    if after != before:
        os.sched_setscheduler(0, before[0], os.sched_param(before[1]))
        pytest.fail(
            f"the test left the suite's process at (policy, priority) {after}, not {before}"
        )


@pytest.fixture
def twin() -> Twin:
    t = Twin(render_size=(96, 96))
    yield t
    t.close()


@pytest.fixture
def explore_killed_at() -> Callable[..., None]:
    """``kill(args, run, size)``: ``ergo explore ARGS --out RUN`` in a child process, killed
    with SIGKILL once ``RUN/history.bin`` holds ``size`` bytes (or after 120 s): a crash in the
    middle of a run, for the resume tests."""

    def kill(args: list[str], run: Path, size: int) -> None:
        cmd = [sys.executable, "-m", "explore.cli", "explore", *args, "--out", str(run)]
        proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        hist, deadline = run / HISTORY_FILE, time.monotonic() + 120
        while time.monotonic() < deadline and (not hist.exists() or hist.stat().st_size < size):
            time.sleep(0.005)
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()

    return kill
