"""The Ergo Jr's robot types for LeRobot (``--robot.type=...``), each a config registered with
``RobotConfig.register_subclass``:

- ``ergo_jr_dynamixel``: the arm's XL-320 servos on a Dynamixel serial bus (``--robot.port``);
- ``ergo_jr_canopen``: the arm's CiA 402 drives on a CAN bus (``--robot.can``);
- ``ergo_jr_twin``: the MuJoCo twin in this process, with its overhead camera.

``--robot.id`` is the rig id: the folder of the rig's calibration files (``ergo calibrate ...
--rig-id ID``), under ``--robot.calibration_dir`` when given, else ``ERGO_CALIBRATION_DIR``, else
``~/.config/ergo-explore/calibration`` (``robot/calibration_files.py``). LeRobot's own
calibration folder is not used.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from lerobot.cameras import CameraConfig
from lerobot.robots import RobotConfig

from explore.rigs.video import VIDEO_SIDE
from lerobot_robot_ergo_jr.features import IMAGE_SIDE
from robot.canopen.bus import DEFAULT_BITRATE
from robot.dynamixel.bus import DEFAULT_BAUD
from robot.spec import ERGO_JR_MAX_STEP
from robot.torque_guardian import ON_DEATH

TWIN_RIG_ID = "twin"  # the twin's rig id by default (explore/rigs/rig.py RigConfig)


def check_image_side(side: int, key: str = "image_side") -> None:
    """A one-line ``ValueError`` unless ``side`` can be a recorded frame's side (the rigs'
    ``record_video`` rule: even, within ``VIDEO_SIDE``)."""
    lo, hi = VIDEO_SIDE
    if not (isinstance(side, int) and lo <= side <= hi and side % 2 == 0):
        raise ValueError(f"{key} must be an even number of pixels in [{lo}, {hi}], got {side!r}")


def check_max_step(value: object) -> None:
    """``max_relative_target`` must be one number in (0, ``ERGO_JR_MAX_STEP``] rad: the step
    bound of every command, which LeRobot may tighten but not loosen nor turn off."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ValueError(
            f"max_relative_target must be one number of radians in (0, {ERGO_JR_MAX_STEP}], got "
            f"{value!r} (the Ergo Jr's step bound is the same for every joint, never off)"
        )
    if not 0 < value <= ERGO_JR_MAX_STEP:
        raise ValueError(
            f"max_relative_target must be in (0, {ERGO_JR_MAX_STEP}] rad, got {value} (the "
            f"arm's step bound, robot/spec.py ERGO_JR_MAX_STEP, may be tightened, not loosened)"
        )


@dataclass(kw_only=True)
class ErgoJrBaseConfig(RobotConfig):
    """What the three robot types share.

    Attributes:
        max_relative_target: the largest change of any joint's goal between two commands, rad
            (default ``ERGO_JR_MAX_STEP``, 0.15): every action is clamped to the joint limits
            (the rig's joint calibration narrows them) and to this step from the previous
            command. Smaller values only.
        image_side: side of the overhead frame, pixels (default 64).
        cameras: more cameras, LeRobot's own (``{name: {type: opencv, ...}}``), observed under
            their names.
    """

    max_relative_target: float = ERGO_JR_MAX_STEP
    image_side: int = IMAGE_SIDE
    cameras: dict[str, CameraConfig] = field(default_factory=dict)

    def __post_init__(self) -> None:
        super().__post_init__()
        check_max_step(self.max_relative_target)
        check_image_side(self.image_side)


@dataclass(kw_only=True)
class ErgoJrBusConfig(ErgoJrBaseConfig):
    """A physical arm (or ``ergo twin serve``'s emulated one) on a bus.

    Attributes:
        id: the rig id (required): its joint calibration is ``<root>/<id>/joints.json``.
        camera: the overhead camera, as ``ergo`` takes it: a device index, a video file or a
            URL (``http://127.0.0.1:PORT/stream.mjpg`` from ``ergo twin serve``); None: no
            overhead frame in the observation.
        on_crash: what the servos do if this process dies without turning torque off: ``limp``
            (default) or ``hold`` (docs/real_arm.md).
    """

    camera: str | None = None
    on_crash: str = "limp"

    def __post_init__(self) -> None:
        super().__post_init__()
        if not self.id:
            raise ValueError(
                f"{self.type} needs --robot.id=ID, the rig id its joint calibration is kept under "
                "(lerobot-calibrate or ergo calibrate joints --rig-id ID)"
            )
        if self.id == TWIN_RIG_ID:
            raise ValueError(f"--robot.id={TWIN_RIG_ID} is the twin's: give the arm its own id")
        if self.on_crash not in ON_DEATH:
            raise ValueError(
                f"on_crash must be one of {', '.join(ON_DEATH)}, got {self.on_crash!r}"
            )


@RobotConfig.register_subclass("ergo_jr_dynamixel")
@dataclass(kw_only=True)
class ErgoJrDynamixelConfig(ErgoJrBusConfig):
    """The arm's XL-320 servos on a Dynamixel Protocol 2.0 bus.

    Attributes:
        port: the serial port, e.g. /dev/ttyUSB0 or the pty ``ergo twin serve --bus dynamixel``
            prints.
        baud: bit/s (default 1000000).
        model: the servos' model (default XL-320).
    """

    port: str
    baud: int = DEFAULT_BAUD
    model: str = "XL-320"


@RobotConfig.register_subclass("ergo_jr_canopen")
@dataclass(kw_only=True)
class ErgoJrCanopenConfig(ErgoJrBusConfig):
    """The arm's CiA 402 drives on a CAN bus.

    Attributes:
        can: python-can ``INTERFACE:CHANNEL``, e.g. socketcan:can0, slcan:/dev/ttyACM0, or
            slcan:/dev/pts/N from ``ergo twin serve --bus canopen``.
        bitrate: CAN bit/s for interfaces that take one (default 1000000).
    """

    can: str
    bitrate: int = DEFAULT_BITRATE


@RobotConfig.register_subclass("ergo_jr_twin")
@dataclass(kw_only=True)
class ErgoJrTwinConfig(ErgoJrBaseConfig):
    """The MuJoCo twin in this process, in real time (its physics follows the wall clock).

    Attributes:
        id: the rig id whose fitted servos the twin takes (``ergo calibrate dynamics``), when it
            has a ``dynamics.json``; default ``twin``, the nominal servos.
        camera: observe the overhead camera (default True).
    """

    camera: bool = True

    def __post_init__(self) -> None:
        if not self.id:
            self.id = TWIN_RIG_ID
        super().__post_init__()
