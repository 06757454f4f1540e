"""The ``dynamixel`` rig: a real (or emulated) Ergo Jr on a serial port, a camera and the wall
clock."""

from __future__ import annotations

from dataclasses import dataclass, field

from explore.options import BadOption
from explore.rigs.ball import camera_sensor
from explore.rigs.clock import RealClock
from explore.rigs.hardware import HardwareOptions, check_rig_id, joint_setup, rig_camera, scene
from explore.rigs.rig import Rig, RigConfig, RigError
from explore.rigs.video import camera_video_frame
from robot.bus_flags import DEFAULT_BAUD

POSITIVE = "a positive integer"
PHYSICAL = True  # an arm on a host: one trial at a time, on the host that has it
__all__ = ["PHYSICAL", "Options", "make_rig", "scene"]


@dataclass(frozen=True)
class Options(HardwareOptions):
    """Options of the Dynamixel rig (and those of every physical rig: ``HardwareOptions``).

    Attributes:
        port: serial device of the Dynamixel bus, e.g. ``/dev/ttyUSB0`` or the pty printed by
            ``ergo twin serve --bus dynamixel`` (required).
        baud: bit/s (default 1_000_000, the Ergo Jr's XL-320 setting).
        model: servo model (default "XL-320").
        latency_s: the least slack added to every bus timeout, s (default 0.020, see
            ``robot.dynamixel.bus.DEFAULT_LATENCY_S``); the bus raises it to the reply latency
            it measures, up to ``robot.dynamixel.bus.MAX_LATENCY_S``.
        retries: retries per bus call after a lost or corrupt reply (default 2).
    """

    port: str | None = None
    baud: int = field(default=DEFAULT_BAUD, metadata={"expected": POSITIVE})
    model: str = "XL-320"
    latency_s: float | None = None
    retries: int | None = None

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.baud <= 0:
            raise BadOption("baud", f"must be {POSITIVE}, got {self.baud!r}")


def make_rig(config: RigConfig, options: Options) -> Rig:
    """Build (not connect) the rig (see ``Options``); its arm clamps to the joint calibration's
    limits (``explore.rigs.hardware.joint_setup``)."""
    from robot.dynamixel.arm import DynamixelArm
    from robot.errors import BusError

    if not options.port:
        raise RigError(
            "dynamixel rig needs options.port, the serial port of the servos (e.g. /dev/ttyUSB0, "
            "or the pty printed by `ergo twin serve --bus dynamixel`)"
        )
    check_rig_id(config)
    joints = joint_setup(config, options)  # DynamixelArm: servo = direction * joint + offset
    bus = {}
    if options.latency_s is not None:
        bus["latency_s"] = options.latency_s
    if options.retries is not None:
        bus["retries"] = options.retries
    try:
        arm = DynamixelArm(
            options.port,
            options.baud,
            spec=joints.spec,
            model=options.model,
            directions=joints.directions,
            offsets=joints.offsets,
            **bus,
        )
    except (ValueError, KeyError, TypeError, BusError) as exc:
        raise RigError(f"dynamixel rig: {exc}") from exc
    arm.on_crash = options.on_crash
    camera = rig_camera(options, config.name)
    sensor = camera_sensor(config, camera)
    return Rig(
        arm=arm, camera=camera, clock=RealClock(), config=config,
        sensor=sensor,
        video_frame=camera_video_frame(camera, options.record_video, sensor.observe),
    )  # fmt: skip
