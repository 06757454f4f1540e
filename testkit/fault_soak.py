"""Soak: N episodes with ~1% faults; a failed episode is retried by resuming the run
(``tests/stress/soak.py`` runs it and prints the result).

``bus="serial"``: the real ``DynamixelArm`` and ``DynamixelBus`` (retries, typed errors)
talk Protocol 2.0 to ``sim.dynamixel.emulator.DynamixelEmulator`` driving the twin, through
its in-process ``EmulatedSerial`` (the byte stream of the pty server without the pty and
without real-time pacing). Status packets are dropped, corrupted and sent late (past the
timeout), each at rate/3.
``bus="arm"``: the ``sim`` rig's arm wrapped in ``robot.faulty_arm.FaultyArm`` (reads and sends
raise at the rate).

When an episode fails after the bus's retries, the rig is disconnected (torque off), and
the run resumes from its folder with a freshly built rig, as ``ergo explore --resume``
would. Reported: episodes stored, lost completed episodes (history checked 0..N-1 with
valid checksums: must be 0), failures and their messages, the arm's fault counters
(``Arm.fault_counts``: bus calls, retries, timeouts, CRC errors, and the total duration of
the calls that needed a retry), time lost to failed episodes (from the last stored episode
before a failure to the first episode of the resumed run, less one typical episode), wall
time.
"""

from __future__ import annotations

import collections
import time
from pathlib import Path

from explore.rigs.ball import TwinSensor
from explore.rigs.clock import TwinClock
from explore.rigs.rig import Rig, RigConfig
from explore.runs.config import RunConfig
from explore.runs.open_run import open_run
from explore.runs.store import RunStore
from robot.errors import RobotError
from sim.camera import SimCamera
from sim.twin import Twin

RENDER = (64, 64)  # the recorded image is 64 x 64; larger renders only cost time


def build_rig(bus: str, rate: float, seed: int) -> Rig:
    """The twin behind a faulty link: the emulated serial bus ("serial") or a ``FaultyArm``
    ("arm"), faults at ``rate`` drawn from ``seed``."""
    twin = Twin(render_size=RENDER)
    if bus == "serial":
        from robot.dynamixel.arm import DynamixelArm
        from sim.dynamixel.emulator import DynamixelEmulator, EmulatedSerial, FaultConfig

        third = rate / 3
        faults = FaultConfig(drop_rate=third, corrupt_rate=third, late_rate=third, seed=seed)
        emulator = DynamixelEmulator(twin, faults=faults)
        # latency 2 ms: the in-process fake answers at once, so a lost reply costs only this
        # (a late one comes 30 ms late: past the timeout, it is retried like a lost one)
        arm = DynamixelArm("emulated", connection=EmulatedSerial(emulator), latency_s=0.002)
    else:
        from robot.faulty_arm import FaultyArm
        from sim.arm import SimArm

        arm = FaultyArm(SimArm(twin), rate=rate, seed=seed)
    camera = SimCamera(twin)
    return Rig(arm=arm, camera=camera, clock=TwinClock(twin), config=RigConfig(name="sim"),
               sensor=TwinSensor(twin, camera))  # fmt: skip


def soak(episodes: int, rate: float, bus: str, seed: int, out: Path) -> dict:
    """Soak ``episodes`` RPE episodes into the new run folder ``out`` at fault ``rate`` on
    ``bus`` ("serial" or "arm"); returns the report (see the module docstring)."""
    config = RunConfig(seed=seed, episodes=episodes)
    store = None
    failures: collections.Counter[str] = collections.Counter()
    counters: collections.Counter[str] = collections.Counter()  # summed over attempts
    last_stored = time.perf_counter()
    lost_s = 0.0
    pending_failure_at: float | None = None
    t0 = time.perf_counter()

    def on_episode(_p: object) -> None:
        nonlocal last_stored, lost_s, pending_failure_at
        now = time.perf_counter()
        if pending_failure_at is not None:
            # from the last good episode to the end of the first one after recovery, minus
            # one normal episode: the time recovery cost
            typical = (now - t0) / max(len(store) if store is not None else 0, 1)
            lost_s += max(0.0, now - pending_failure_at - typical)
            pending_failure_at = None
        last_stored = now

    attempts = 0
    while store is None or len(store) < episodes:
        attempts += 1
        # give up on a soak that cannot progress: at the arm level at rate 0.01 an episode's
        # ~130 reads and sends see a fault in 3 episodes of 4 (0.99^130; 15 episodes took 47
        # attempts, 53 once the movement read the joints before its first command); the
        # limit bounds a soak's time, it is no part of what the soak checks
        if attempts > 50 + 3 * episodes:
            raise RuntimeError("soak: too many failures, giving up")
        # a fresh rig per attempt, as a resumed process opens the port again (the fault
        # draws get a new seed per attempt so a failure does not replay identically)
        rig = build_rig(bus, rate, seed * 1000 + attempts)
        run = open_run(out, config, mode="new" if store is None else "resume", rig=rig)
        store = run.store
        try:
            run.explore(on_episode=on_episode)
        except RobotError as exc:
            failures[type(exc).__name__ + ": " + str(exc).split(" on ")[0][:90]] += 1
            pending_failure_at = last_stored
        finally:
            run.close()
            counters.update(rig.arm.fault_counts())
            if bus == "arm":
                counters.update(rig.arm.counts)  # type: ignore[attr-defined]
            rig.sensor.twin.close()  # type: ignore[union-attr]
    wall = time.perf_counter() - t0
    check = RunStore.read(out)  # verifies every checksum, cuts nothing
    ids = [r.episode for r in check]
    check.close()
    lost = episodes - len(set(ids)) if ids == sorted(set(ids)) else -1
    result = {
        "bus": bus,
        "fault_rate": rate,
        "episodes": len(ids),
        "lost_episodes": lost,
        "history_ok": ids == list(range(episodes)),
        "failed_attempts": sum(failures.values()),
        "failures": dict(failures),
        "time_lost_to_recovery_s": round(lost_s, 2),
        "wall_s": round(wall, 1),
        "episodes_per_s": round(len(ids) / wall, 2),
    }
    result["counters"] = {
        k: round(v, 3) if isinstance(v, float) else v for k, v in counters.items()
    }
    return result
