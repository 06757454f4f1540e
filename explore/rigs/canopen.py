"""The ``canopen`` rig: six CiA 402 drives on a CAN bus (``CanArm``), a camera (OpenCV device
index, file or URL) and the wall clock."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from explore.rigs.ball import camera_sensor
from explore.rigs.clock import RealClock
from explore.rigs.hardware import (
    HardwareOptions,
    check_rig_id,
    joint_setup,
    per_joint,
    rig_camera,
    scene,
)
from explore.rigs.rig import Rig, RigConfig, RigError
from explore.rigs.video import camera_video_frame

PHYSICAL = True  # an arm on a host: one trial at a time, on the host that has it
__all__ = ["PHYSICAL", "Options", "make_rig", "scene"]


@dataclass(frozen=True)
class Options(HardwareOptions):
    """Options of the CANopen rig (and those of every physical rig: ``HardwareOptions``).

    Attributes:
        can: python-can bus ``INTERFACE:CHANNEL`` (required), e.g. ``socketcan:can0``,
            ``slcan:/dev/ttyACM0``, or ``slcan:/dev/pts/N`` from ``ergo twin serve --bus
            canopen``.
        bitrate: CAN bit/s for interfaces that take one (default 1000000).
        node_ids: the six node ids of m1..m6 (default 1..6).
        eds: the drives' EDS file (default: ``robot/canopen/ergo_drive.eds``, the emulated drive).
        pdo_timeout_s, following_error_window: see ``robot.canopen.arm.CanArmConfig``.
        heartbeat_ms: producer heartbeat time written to the drives, ms (default 100 on a real
            adapter; ``robot.canopen.arm.PTY_SETTINGS`` on a pty, i.e. the emulator).
    """

    can: str | None = None
    bitrate: int | None = None
    node_ids: tuple[int, ...] | None = None
    eds: str | None = None
    pdo_timeout_s: float | None = None
    following_error_window: float | None = None
    heartbeat_ms: int | None = None


def can_offsets(directions: np.ndarray, servo_offsets: np.ndarray) -> np.ndarray:
    """A joint calibration's offsets (servo angle at joint zero, rad: ``calibration.joints``,
    ``servo = direction * joint + offset``) as ``CanArm`` takes them (the joint angle at drive
    position 0, ``joint = offset + direction * drive``): ``-direction * offset``, shape (n,)."""
    return -np.asarray(directions, float) * np.asarray(servo_offsets, float)


def make_rig(config: RigConfig, options: Options) -> Rig:
    """Build (not connect) the rig; bad or missing options are one-line ``RigError``s."""
    from robot.canopen.arm import CanArm, config_for
    from robot.canopen.bus import CanBusError, parse_can_spec
    from robot.spec import ERGO_JR_JOINTS

    if not options.can:
        raise RigError(
            "rig 'canopen' needs option can: INTERFACE:CHANNEL, e.g. --can socketcan:can0 or "
            "--can slcan:/dev/ttyACM0"
        )
    check_rig_id(config)
    n = len(ERGO_JR_JOINTS)
    joints = joint_setup(config, options, can_offsets)
    arm_config = {
        "node_ids": per_joint(options, "node_ids", n, config.name),
        "directions": joints.directions,
        "offsets": joints.offsets,
        "heartbeat_ms": options.heartbeat_ms,
        "pdo_timeout_s": options.pdo_timeout_s,
        "following_error_window": options.following_error_window,
        "eds": Path(options.eds) if options.eds is not None else None,
    }
    camera = rig_camera(options, config.name)
    try:
        bus_spec = parse_can_spec(options.can, options.bitrate)
        arm = CanArm(bus_spec, spec=joints.spec, config=config_for(bus_spec, **arm_config))
    except (CanBusError, ValueError) as exc:
        raise RigError(f"rig 'canopen': {exc}") from exc
    arm.on_crash = options.on_crash
    sensor = camera_sensor(config, camera)
    return Rig(
        arm=arm, camera=camera, clock=RealClock(), config=config,
        sensor=sensor,
        video_frame=camera_video_frame(camera, options.record_video, sensor.observe),
    )  # fmt: skip
