"""``ergo calibrate dynamics --rig-id X``: record the excitation on an arm (the twin in
process, a Dynamixel bus with ``--port``, a CANopen bus with ``--can``), fit the twin's servos
to it, and write ``dynamics.json`` of rig X, the recording beside it
(``dynamics_recording.npz``) and the report (``dynamics_report/``). With ``--recording FILE``
it fits an earlier recording without an arm.

Every failure is one line naming the fix, and leaves the previous ``dynamics.json`` as it
was; a recording cut short is kept aside (``dynamics_recording.partial.npz``), never over the
last complete one.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import Any

RECORDING_FILE = "dynamics_recording.npz"
PARTIAL_FILE = "dynamics_recording.partial.npz"
REPORT_DIR = "dynamics_report"
# reads per 25 ms control tick: the twin steps 5 ms, so 5 (200 Hz); a bus reads in a few ms
# (a sync read of six XL-320 at 1 Mbit/s, one CANopen SYNC cycle), so 2 (80 Hz; guess)
TWIN_READS_PER_TICK = 5
BUS_READS_PER_TICK = 2


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The flags of ``ergo calibrate dynamics`` (besides --rig-id and --dir)."""
    from calibration.dynamics.excitation import REPEATS
    from robot.bus_flags import add_bus_arguments

    add_bus_arguments(p, required=False)
    p.add_argument("--model", default="XL-320", help="Dynamixel model")
    p.add_argument(
        "--recording", type=Path, default=None,
        help="fit this recording (.npz of an earlier run) instead of recording one",
    )  # fmt: skip
    p.add_argument(
        "--reads-per-tick", type=int, default=None,
        help=f"readings per 25 ms tick (default {TWIN_READS_PER_TICK} on the twin, "
        f"{BUS_READS_PER_TICK} on a bus)",
    )  # fmt: skip
    p.add_argument(
        "--joints", nargs="+", default=None, metavar="NAME",
        help="excite only these joints (default all); the others keep the nominal servos",
    )  # fmt: skip
    p.add_argument(
        "--repeats", type=int, default=REPEATS, metavar="N",
        help=f"play each joint's steps and multi-sine N times (default {REPEATS}: 107 s in all; "
        "each repeat 32 s, docs/dynamics.md)",
    )  # fmt: skip
    p.add_argument("--no-report", action="store_true", help="write no report")
    p.add_argument(
        "--record-only", action="store_true",
        help="record and check the recording, fit nothing (fit it later with --recording)",
    )  # fmt: skip


def _arm(args: argparse.Namespace) -> tuple[Any, Any, str]:
    """(arm, clock, backend) for the flags: the in-process twin without --port/--can."""
    from calibration import store
    from calibration.joints import load_joints_file
    from robot.bus_flags import bus_from_args
    from robot.spec import ergo_jr_spec

    bus = bus_from_args(args)
    if bus is None:
        from sim.arm import SimArm
        from sim.twin import Twin

        twin = Twin()

        class _TwinClock:  # time is the twin's (as explore.rigs.clock.TwinClock)
            def now(self) -> float:
                return twin.time

            def advance(self, seconds: float) -> None:
                twin.step(seconds)

        return SimArm(twin), _TwinClock(), "twin"
    spec = ergo_jr_spec()
    path = store.calibration_path("joints", args.rig_id, args.dir)
    try:
        cal = load_joints_file(path, spec)
    except store.CalibrationMissing:
        raise store.CalibrationError(
            f"no joint calibration {path}: the fit needs true joint angles (gravity acts on "
            f"them); run `ergo calibrate joints --rig-id {args.rig_id}` first"
        ) from None
    spec = cal.apply_to(spec)
    directions = tuple(float(d) for d in cal.directions)
    if bus.kind == "dynamixel":
        from robot.dynamixel.arm import DynamixelArm

        arm = DynamixelArm(
            bus.where, bus.rate, spec=spec, model=args.model, directions=directions,
            offsets=tuple(float(o) for o in cal.offsets),
        )  # fmt: skip
    else:
        from robot.canopen.arm import CanArm, config_for

        offsets = tuple(float(-d * o) for d, o in zip(cal.directions, cal.offsets, strict=True))
        # on the emulator's pty, its settings (500 ms heartbeat, 2 s SDO), as every command
        config = config_for(bus.where, directions=directions, offsets=offsets)
        arm = CanArm(bus.where, bus.rate, spec=spec, config=config)
    import time

    class _RealClock:  # wall time on a monotonic schedule (as explore.rigs.clock.RealClock)
        def __init__(self) -> None:
            self.deadline = time.monotonic()

        def now(self) -> float:
            return time.monotonic()

        def advance(self, seconds: float) -> None:
            self.deadline = max(self.deadline + seconds, time.monotonic() - seconds)
            delay = self.deadline - time.monotonic()
            if delay > 0:
                time.sleep(delay)

    return arm, _RealClock(), bus.kind


def _joint_indices(spec: Any, joints: list[str] | None) -> list[int] | None:
    from calibration.store import CalibrationError

    if joints is None:
        return None
    unknown = [j for j in joints if j not in spec.names]
    if unknown:
        raise CalibrationError(
            f"--joints: unknown joint(s) {', '.join(unknown)}; the arm's are "
            f"{', '.join(spec.names)}"
        )
    return [spec.names.index(j) for j in dict.fromkeys(joints)]


def run(args: argparse.Namespace) -> int:
    """The command; raises ``CalibrationError`` (one line) on any failure."""
    from calibration import store
    from calibration.dynamics import checks, excitation
    from calibration.dynamics.fit import FitError, fit
    from calibration.dynamics.recording import Recording, RecordingError, record

    if args.repeats < 1:  # before the bus is opened
        raise store.CalibrationError(f"--repeats must be 1 or more, got {args.repeats}")
    path = store.calibration_path("dynamics", args.rig_id, args.dir)
    kept = f"{path} unchanged" if path.exists() else f"no {path.name} written"
    folder = path.parent
    if args.recording is not None:
        rec_path = args.recording
        rec = Recording.load_file(rec_path)
    else:
        arm, clock, backend = _arm(args)
        reads = args.reads_per_tick or (
            TWIN_READS_PER_TICK if backend == "twin" else BUS_READS_PER_TICK
        )
        segments = excitation.plan(
            arm.spec, _joint_indices(arm.spec, args.joints), repeats=args.repeats
        )
        total = sum(len(s.commands) for s in segments) / 40.0
        print(f"recording on {backend}: {len(segments)} segments, {total:.0f} s; Ctrl-C stops")
        import time

        t0 = time.monotonic()
        try:
            with arm:
                arm.set_torque(True)
                rec = record(
                    arm, clock, segments, reads,
                    {"rig_id": args.rig_id, "backend": backend, "repeats": args.repeats},
                    notify=lambda m: print(m, flush=True),
                )  # fmt: skip
        except RecordingError as exc:
            partial = getattr(exc, "partial", None)
            where = ""
            if partial is not None:
                where = f"; the part recorded is in {partial.save(folder / PARTIAL_FILE)}"
            raise RecordingError(
                f"{exc}: record again once the arm is free and the bus plugged in{where}; {kept}"
            ) from None
        rec.meta["record_s"] = round(time.monotonic() - t0, 2)
        rec_path = rec.save(folder / RECORDING_FILE)
        print(
            f"recorded {len(rec.measured_t)} readings in {rec.meta['record_s']:.1f} s: {rec_path}"
        )
    try:
        checks.check_recording(rec)
        if getattr(args, "record_only", False):
            print(
                f"recording checked, not fitted: fit it with ergo calibrate dynamics --rig-id "
                f"{args.rig_id} --recording {rec_path}"
            )
            return 0
        print("fitting the servos (mujoco.sysid) ...", flush=True)
        result = fit(rec)
    except (RecordingError, FitError) as exc:
        what = "fit failed" if isinstance(exc, FitError) else "recording refused"
        raise store.CalibrationError(f"{what}: {exc}; {kept}") from None
    payload = result.to_dict()
    payload["recording"] = {
        "path": str(Path(rec_path).resolve()),
        "sha256": store.file_sha256(rec_path),
        "backend": rec.meta.get("backend"),
        "record_s": rec.meta.get("record_s"),
    }
    saved = store.save("dynamics", args.rig_id, payload, args.dir)
    print(describe(payload))
    if not args.no_report:
        from calibration.dynamics.report import write_report

        png, html = write_report(rec, result, folder / REPORT_DIR)
        print(f"report: {html} ({png.name})")
    print(f"saved {saved}")
    return 0


def describe(data: dict[str, Any]) -> str:
    """One paragraph of a dynamics payload (``ergo calibrate dynamics`` and ``show``)."""
    from robot.spec import ERGO_JR_JOINTS

    s = data["servos"]
    rms = data["held_out_rms_rad"]
    per = "; ".join(
        f"{name} kp {s['kp'][i]:.2f} damping {s['damping'][i]:.3f} armature "
        f"{s['armature'][i] * 1e3:.2f}e-3 friction {s['frictionloss'][i] * 1e3:.1f}e-3"
        for i, name in enumerate(ERGO_JR_JOINTS)
    )
    ratio = rms["nominal"] / rms["fitted"] if rms["fitted"] > 0 else math.inf
    loose = [
        name.replace(".", " ")
        for name, why in data.get("unidentified", {}).items()
        if not why.startswith("not recorded")
    ]
    return (
        f"delay {s['delay_s'] * 1e3:.1f} ms; {per}; held-out RMS "
        f"{math.degrees(rms['fitted']):.3f} deg fitted, {math.degrees(rms['nominal']):.3f} deg "
        f"nominal ({ratio:.1f}x)"
        + (
            f"; not identified by the recording (wide intervals, no measurement): "
            f"{', '.join(loose)}"
            if loose
            else ""
        )
    )
