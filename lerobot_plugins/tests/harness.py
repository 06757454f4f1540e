"""What the plugins' tests share: LeRobot's and Hugging Face's folders and the rigs'
calibration root in a temporary folder, set when this module is first imported (by conftest.py,
before lerobot is: it reads them at import), the Hub offline; ``run_lerobot``, which runs a
LeRobot command and keeps its line for the session's summary (the CI lines of the LeRobot
user's path)."""

from __future__ import annotations

import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
SCRATCH = Path(tempfile.mkdtemp(prefix="ergo-lerobot-tests-"))
ENV = {
    "HF_HOME": str(SCRATCH / "hf"),
    "HF_LEROBOT_HOME": str(SCRATCH / "lerobot"),
    "HF_LEROBOT_CALIBRATION": str(SCRATCH / "lerobot-calibration"),
    "HF_HUB_OFFLINE": "1",
    "WANDB_MODE": "disabled",
    "ERGO_CALIBRATION_DIR": str(SCRATCH / "ergo-calibration"),
    "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl"),
    "PYTHONUNBUFFERED": "1",
}
os.environ.update(ENV)
BIN = Path(sys.executable).parent
# One LeRobot command, against hangs (not a target): the slowest, lerobot-train's few steps or
# a bus calibration by the served twin's hands, take a minute or two on a loaded 2-core machine.
COMMAND_BOUND_S = 900.0
RAN: list[str] = []


def run_lerobot(
    command: str, *args: str, timeout: float = COMMAND_BOUND_S, env: dict | None = None
) -> subprocess.CompletedProcess[str]:
    """``lerobot-COMMAND ARGS`` with stdin closed, its output captured; the line is kept for the
    session's summary."""
    t0 = time.monotonic()
    done = subprocess.run(
        [str(BIN / f"lerobot-{command}"), *args],
        stdin=subprocess.DEVNULL,
        capture_output=True,
        text=True,
        timeout=timeout,
        env={**os.environ, **(env or {})},
        cwd=SCRATCH,
    )
    note(f"lerobot-{command} {' '.join(args)}", done.returncode, time.monotonic() - t0)
    return done


def note(line: str, rc: int | None, seconds: float) -> None:
    """Keep a command's line for the session's summary (pytest's temporary folders as $TMP)."""
    line = re.sub(r"/\S*/pytest-\d+/", "$TMP/", line)
    RAN.append(f"$ {line}  (rc {rc}, {seconds:.0f} s)")


def tail(done: subprocess.CompletedProcess[str], n: int = 3000) -> str:
    """The end of a command's output, for an assertion's message."""
    return (done.stdout + done.stderr)[-n:]


def nominal_joint_calibration(rig_id: str) -> Path:
    """Write the joint calibration ``ergo calibrate joints`` finds on a nominal served twin
    (servo angle = joint angle, the spec's limits) for ``rig_id``, without the minute its
    hands take: for the tests whose subject is not the calibration."""
    import numpy as np

    from calibration import store
    from calibration.joints import JointCalibration
    from robot.spec import ergo_jr_spec

    spec = ergo_jr_spec()
    cal = JointCalibration(
        tuple(spec.names), np.zeros(spec.n), np.ones(spec.n), spec.lower.copy(), spec.upper.copy()
    )
    return store.save("joints", rig_id, cal.to_dict())


def bus_flag(rig: object, device: str) -> str:
    """``--robot.port=PTY`` / ``--robot.can=slcan:PTY`` (or ``--teleop...``) of a served rig."""
    kind = "port" if rig.bus_kind == "dynamixel" else "can"  # type: ignore[attr-defined]
    return f"--{device}.{kind}={rig.where}"  # type: ignore[attr-defined]


def report_dataset(dataset: Path) -> dict:
    """The dataset's ``meta/info.json``, its robot type, frames and features kept for the
    session's summary (read as LeRobot wrote it)."""
    import json

    info = json.loads((dataset / "meta/info.json").read_text())
    feats = ", ".join(
        f"{k} {v['dtype']} {v['shape']}"
        + (f" {v['names']}" if k in ("action", "observation.state") else "")
        for k, v in info["features"].items()
        if k not in ("timestamp", "frame_index", "episode_index", "index", "task_index")
    )
    RAN.append(
        f"  -> {dataset.name}/meta/info.json: robot_type {info['robot_type']}, "
        f"{info['total_episodes']} episode(s), {info['total_frames']} frames at {info['fps']} "
        f"fps; {feats}"
    )
    return info


def report(line: str) -> None:
    """A result line under the last command in the session's summary."""
    RAN.append(f"  -> {line}")
