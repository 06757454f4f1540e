"""Recording the excitation through ``robot.Arm``: commanded and measured positions (and loads
where the servos report them) with timestamps, saved as one documented ``.npz`` file.

Why an ``.npz`` and not the run store or the LeRobot export: a recording is not an exploration
run (no episodes, goals or camera frames) and its reader is the fit; ``numpy.load`` reads it
anywhere (no pyarrow, no project code), each array named below, and one file is hashed into the
twin calibration that was fitted from it. The layout (``FORMAT``, version ``VERSION``):

- ``joint_names``: (n,) str; ``segment_names``: (S,) str (``m1`` .. ``m6``, ``held_out``);
- ``command_t``: (C,) s; ``command``: (C, n) rad, what ``Arm.command`` sent (after its clamp);
  ``command_segment``: (C,) int, the segment of each command;
- ``measured_t``: (M,) s; ``measured``: (M, n) rad; ``load``: (M, n), signed fraction of the
  servo's maximum torque (NaN where the servo does not report it); ``measured_segment``: (M,);
- ``meta``: a JSON string: format, version, rig id, backend, control rate, reads per tick,
  base pose, limits, complete (False for a recording cut short), created (UTC),
  ``position_resolution`` (one raw unit of each joint's position, rad: ``Arm.position_resolution``;
  0 where continuous), notes.

A servo holds its goal in the same raw units it reports its position in (an XL-320's 10-bit
register, a drive's increments): ``servo_goals`` gives the commands as the servos held them.

Times are seconds from the first command, on the arm's clock (the twin's simulated time, or
``time.monotonic`` of the host); a reading's is when the servos sampled it
(``JointState.timestamp``: a Dynamixel read's request, a CANopen SYNC), a command's when it was
sent; joint angles are the calibrated joint angles (rad).
"""

from __future__ import annotations

import io
import json
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from calibration.dynamics.excitation import Segment
from calibration.store import CalibrationError
from plumbing.files import atomic_write
from robot.arm import Arm
from robot.errors import RobotError
from robot.spec import CONTROL_RATE_HZ

FORMAT = "ergo-explore/dynamics-recording"
VERSION = 1
# Going to the base pose before the first segment: at most this speed (guess: a slow, visible
# move a person can stop), rad/s.
APPROACH_SPEED = 0.5


class RecordingError(CalibrationError):
    """A recording could not be made, read or used; the message is one line."""


@dataclass
class Recording:
    """A recording (see the module docstring for the arrays and their units)."""

    joint_names: list[str]
    segment_names: list[str]
    command_t: np.ndarray
    command: np.ndarray
    command_segment: np.ndarray
    measured_t: np.ndarray
    measured: np.ndarray
    load: np.ndarray
    measured_segment: np.ndarray
    meta: dict[str, Any] = field(default_factory=dict)

    def segment(self, name: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(command_t (C,), command (C, n), measured_t (M,), measured (M, n)) of one segment."""
        k = self.segment_names.index(name)
        c = self.command_segment == k
        m = self.measured_segment == k
        return self.command_t[c], self.command[c], self.measured_t[m], self.measured[m]

    def segment_load(self, name: str) -> np.ndarray:
        """The loads of one segment, shape (M, n) (NaN where unknown)."""
        return self.load[self.measured_segment == self.segment_names.index(name)]

    def save(self, path: str | Path) -> Path:
        """Write the ``.npz`` atomically (``plumbing.files.atomic_write``)."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        buf = io.BytesIO()
        np.savez_compressed(
            buf,
            joint_names=np.array(self.joint_names),
            segment_names=np.array(self.segment_names),
            command_t=self.command_t,
            command=self.command,
            command_segment=self.command_segment,
            measured_t=self.measured_t,
            measured=self.measured,
            load=self.load,
            measured_segment=self.measured_segment,
            meta=np.array(json.dumps(self.meta)),
        )
        return atomic_write(path, buf.getvalue())

    @classmethod
    def load_file(cls, path: str | Path) -> Recording:
        """Read a recording; a missing, damaged or foreign file is one line naming it."""
        path = Path(path)
        try:
            with np.load(path, allow_pickle=False) as z:
                meta = json.loads(str(z["meta"]))
                if meta.get("format") != FORMAT:
                    raise RecordingError(
                        f"{path}: not a dynamics recording ({meta.get('format')!r})"
                    )
                if int(meta.get("version", 0)) > VERSION:
                    raise RecordingError(
                        f"{path}: recording version {meta['version']} is newer than this "
                        "program reads: upgrade"
                    )
                rec = cls(
                    joint_names=[str(s) for s in z["joint_names"]],
                    segment_names=[str(s) for s in z["segment_names"]],
                    command_t=z["command_t"].astype(float),
                    command=z["command"].astype(float),
                    command_segment=z["command_segment"].astype(int),
                    measured_t=z["measured_t"].astype(float),
                    measured=z["measured"].astype(float),
                    load=z["load"].astype(float),
                    measured_segment=z["measured_segment"].astype(int),
                    meta=meta,
                )
        except FileNotFoundError:
            raise RecordingError(
                f"no recording {path}: record one with ergo calibrate dynamics --rig-id ID"
            ) from None
        except (OSError, ValueError, KeyError, json.JSONDecodeError) as exc:
            raise RecordingError(
                f"{path}: not a readable dynamics recording ({type(exc).__name__}: {exc}): "
                "record again with ergo calibrate dynamics"
            ) from None
        n = len(rec.joint_names)
        if rec.command.shape != (len(rec.command_t), n) or rec.measured.shape != (
            len(rec.measured_t),
            n,
        ):
            raise RecordingError(f"{path}: arrays of inconsistent shapes: record again")
        return rec


def servo_goals(rec: Recording) -> np.ndarray:
    """The commands as the servos held them, shape (C, n), rad: each rounded to the servo's
    own position grid (a goal register holds whole raw units, as the positions it reports), the
    grid's step ``meta["position_resolution"]`` and its phase that of the joint's readings
    (they lie on the same grid: one raw unit is one step of both). A joint whose resolution is
    0 or unknown (the twin, a recording without it) keeps its commands as sent.

    An XL-320's step is 0.29 deg: as large as the dead band its friction leaves (0.0026 rad at
    kp 3.5 N.m/rad is 0.009 N.m), so a fit that ignored it would read the goals' rounding as
    friction (measured on the stand-ins: docs/dynamics.md).
    """
    step = np.asarray(rec.meta.get("position_resolution") or [0.0] * len(rec.joint_names), float)
    goals = np.array(rec.command, float)
    for j, s in enumerate(step):
        if not s > 0.0 or not len(rec.measured):
            continue
        # the readings' phase on the grid: a circular mean (every reading lies on it)
        phase = np.angle(np.mean(np.exp(2j * np.pi * rec.measured[:, j] / s))) * s / (2 * np.pi)
        goals[:, j] = phase + s * np.rint((goals[:, j] - phase) / s)
    return goals


def approach(arm: Arm, clock: Any, target: np.ndarray, rate_hz: float = CONTROL_RATE_HZ) -> None:
    """Take the arm from where it is to ``target`` (n,) rad at ``APPROACH_SPEED``, then hold
    0.5 s (not recorded)."""
    start = arm.read().positions
    dt = 1.0 / rate_hz
    ticks = max(1, int(np.ceil(np.max(np.abs(target - start)) / (APPROACH_SPEED * dt))))
    for k in range(1, ticks + 1):
        arm.command(start + (target - start) * k / ticks)
        clock.advance(dt)
    for _ in range(round(0.5 * rate_hz)):
        arm.command(target)
        clock.advance(dt)


def record(
    arm: Arm,
    clock: Any,
    segments: Sequence[Segment],
    reads_per_tick: int = 1,
    meta: dict[str, Any] | None = None,
    notify: Callable[[str], None] | None = None,
    rate_hz: float = CONTROL_RATE_HZ,
) -> Recording:
    """Play ``segments`` through ``arm`` (connected, torque on) at ``rate_hz`` and record.

    Each control tick sends one command, then reads the arm ``reads_per_tick`` times, evenly
    spread over the tick (``clock.advance``). A stop on the way (Ctrl-C, a safety stop, a bus
    error) raises a one-line ``RecordingError`` saying where it stopped; the partial recording
    is on the exception (``.partial``, ``meta["complete"]`` False) for a caller that keeps it.
    """
    if reads_per_tick < 1:
        raise RecordingError(f"reads per tick must be >= 1, got {reads_per_tick}")
    n = arm.spec.n
    dt = 1.0 / rate_hz
    ct: list[float] = []
    cmd: list[np.ndarray] = []
    cseg: list[int] = []
    mt: list[float] = []
    meas: list[np.ndarray] = []
    load: list[np.ndarray] = []
    mseg: list[int] = []
    info = dict(meta or {})
    info.update(
        format=FORMAT,
        version=VERSION,
        control_rate_hz=rate_hz,
        reads_per_tick=reads_per_tick,
        lower=arm.spec.lower.tolist(),
        upper=arm.spec.upper.tolist(),
        created=datetime.now(UTC).isoformat(timespec="seconds"),
        complete=False,
        position_resolution=np.asarray(arm.position_resolution, float).tolist(),
    )

    def build() -> Recording:
        return Recording(
            joint_names=list(arm.spec.names),
            segment_names=[s.name for s in segments],
            command_t=np.asarray(ct, float) - t0,
            command=np.asarray(cmd, float).reshape(-1, n),
            command_segment=np.asarray(cseg, int),
            measured_t=np.asarray(mt, float) - t0,
            measured=np.asarray(meas, float).reshape(-1, n),
            load=np.asarray(load, float).reshape(-1, n),
            measured_segment=np.asarray(mseg, int),
            meta=info,
        )

    t0 = 0.0
    where = "before the first segment"
    try:
        approach(arm, clock, segments[0].commands[0], rate_hz)
        t0 = clock.now()
        for k, seg in enumerate(segments):
            if notify:
                notify(
                    f"segment {k + 1}/{len(segments)}: {seg.name} ({len(seg.commands) * dt:.1f} s)"
                )
            for i, row in enumerate(seg.commands):
                where = f"in segment {seg.name} at {i * dt:.2f} of {len(seg.commands) * dt:.2f} s"
                ct.append(clock.now())
                cmd.append(arm.command(row))
                cseg.append(k)
                for _ in range(reads_per_tick):
                    clock.advance(dt / reads_per_tick)
                    state = arm.read()
                    mt.append(float(state.timestamp))
                    meas.append(np.asarray(state.positions, float))
                    load.append(np.asarray(state.loads, float))
                    mseg.append(k)
    except (KeyboardInterrupt, RobotError, OSError) as exc:
        why = (
            "interrupted" if isinstance(exc, KeyboardInterrupt) else f"{type(exc).__name__}: {exc}"
        )
        error = RecordingError(f"recording cut short {where} ({why})")
        error.partial = build() if ct else None  # type: ignore[attr-defined]
        raise error from None
    info["complete"] = True
    return build()
