"""LeRobot's teleoperation loop with a leader Ergo Jr over the Dynamixel pty, against our own
control loop's cycle rate over the same bus.

Two ``ergo twin serve --bus dynamixel`` (the follower and the leader, no camera), each with the
joint calibration a nominal twin gets. Measured, one after the other:

- our control loop: ``DynamixelArm.read`` + ``command`` on the follower's pty, as fast as it
  goes (what an exploration's tick does, without the pacing to 40 Hz): cycles per second; and
  the same with a leader read first (the work of a teleoperation loop, in our code);
- ``lerobot-teleoperate`` with ``ergo_jr_leader`` and ``ergo_jr_dynamixel`` at ``--fps 60``
  (LeRobot's default): each loop reads the follower, reads the leader, commands the follower;
  the rate it holds, from the loop times it prints (the first second left out: start-up);
- the same unpaced (``--fps 1000``): what LeRobot's loop with the plugins can do, to set
  against our loop (it talks to two buses a loop, ours to one).

The goal: the teleoperation holds 50 Hz or more (docs/lerobot.md). Run it in the LeRobot venv
(lerobot_plugins/, ``make lerobot-venv``)::

    .venv-lerobot/bin/python bench/bench_lerobot_teleop.py [--seconds 10]
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # testkit/

import numpy as np  # noqa: E402

TARGET_HZ = 50.0  # the goal (docs/lerobot.md)
DEFAULT_FPS = 60  # lerobot-teleoperate's default --fps
LOOP = re.compile(r"Teleop loop time: ([0-9.]+)ms")
WARMUP_S = 1.0  # loops left out at the start (the first one opens the buses)


def write_calibrations(root: Path, ids: list[str]) -> None:
    """The joint calibration of a nominal served twin for each rig id, under ``root``."""
    from calibration import store
    from calibration.joints import JointCalibration
    from robot.spec import ergo_jr_spec

    spec = ergo_jr_spec()
    cal = JointCalibration(
        tuple(spec.names), np.zeros(spec.n), np.ones(spec.n), spec.lower.copy(), spec.upper.copy()
    )
    for rig_id in ids:
        store.save("joints", rig_id, cal.to_dict(), root)


def our_loop(port: str, seconds: float, leader: str | None = None) -> float:
    """Cycles per second of ``DynamixelArm.read`` + ``command`` on ``port`` (torque on, holding
    its pose, a small back-and-forth on m1), after a read of the arm on ``leader`` if given."""
    from contextlib import ExitStack

    from robot.dynamixel.arm import DynamixelArm

    with ExitStack() as stack:
        arm = stack.enter_context(DynamixelArm(port))
        lead = stack.enter_context(DynamixelArm(leader)) if leader else None
        arm.set_torque(True)
        q = arm.read().positions.copy()
        n = 0
        t0 = time.perf_counter()
        while time.perf_counter() - t0 < seconds:
            if lead is not None:
                lead.read()
            arm.read()
            target = q.copy()
            target[0] += 0.05 * (n % 2)
            arm.command(target)
            n += 1
        return n / (time.perf_counter() - t0)


def lerobot_loop(follower: str, leader: str, fps: int, seconds: float) -> tuple[float, np.ndarray]:
    """The rate ``lerobot-teleoperate`` holds at ``fps``, Hz, and its loop times after the
    first second, s."""
    cmd = [
        str(Path(sys.executable).parent / "lerobot-teleoperate"),
        "--robot.type=ergo_jr_dynamixel", f"--robot.port={follower}", "--robot.id=bench-follower",
        "--teleop.type=ergo_jr_leader", f"--teleop.port={leader}", "--teleop.id=bench-leader",
        f"--fps={fps}", f"--teleop_time_s={seconds + WARMUP_S}",
    ]  # fmt: skip
    done = subprocess.run(cmd, capture_output=True, text=True, stdin=subprocess.DEVNULL)
    if done.returncode != 0:
        raise SystemExit(f"lerobot-teleoperate failed: {(done.stdout + done.stderr)[-2000:]}")
    loops = np.array([float(m) / 1000 for m in LOOP.findall(done.stdout)])
    keep = loops[np.cumsum(loops) > WARMUP_S]
    return len(keep) / keep.sum(), keep


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=10.0, help="each measurement, s")
    args = parser.parse_args(argv)
    from testkit.standin_owner import ServedRig

    scratch = Path(tempfile.mkdtemp(prefix="bench-lerobot-"))
    os.environ.update(
        ERGO_CALIBRATION_DIR=str(scratch / "calibration"), HF_HOME=str(scratch / "hf"),
        HF_LEROBOT_HOME=str(scratch / "lerobot"), HF_HUB_OFFLINE="1",
        HF_LEROBOT_CALIBRATION=str(scratch / "lerobot-calibration"),
    )  # fmt: skip
    write_calibrations(scratch / "calibration", ["bench-follower", "bench-leader"])
    flags = ["--no-camera"]
    with (
        ServedRig("dynamixel", None, flags=flags, log=scratch / "f.log") as follower,
        ServedRig("dynamixel", None, flags=flags, log=scratch / "l.log") as leader,
    ):
        ours = our_loop(follower.where, args.seconds)
        ours_teleop = our_loop(follower.where, args.seconds, leader=leader.where)
        paced, loops = lerobot_loop(follower.where, leader.where, DEFAULT_FPS, args.seconds)
        free, _ = lerobot_loop(follower.where, leader.where, 1000, args.seconds)
    load = os.getloadavg()[0]
    p95 = float(np.percentile(loops, 95)) * 1000
    print(f"load average {load:.1f} on {os.cpu_count()} cores")
    print(f"our control loop (DynamixelArm read + command, one pty): {ours:.0f} cycles/s")
    print(f"our loop with a leader read first (two ptys): {ours_teleop:.0f} cycles/s")
    print(
        f"lerobot-teleoperate --fps {DEFAULT_FPS}, leader + follower (two ptys): {paced:.1f} Hz "
        f"(loop p95 {p95:.1f} ms); target >= {TARGET_HZ:.0f} Hz: "
        f"{'met' if paced >= TARGET_HZ else 'NOT met'}"
    )
    print(
        f"lerobot-teleoperate unpaced (--fps 1000): {free:.0f} Hz = {free / ours_teleop:.2f} x our "
        f"loop with a leader, {free / ours:.2f} x our control loop"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
