"""The Ergo Jr's teleoperator types for LeRobot (``--teleop.type=...``):

- ``ergo_jr_leader``: a second Ergo Jr, torque off, moved by hand; its joints read at the loop
  rate are the follower's goal positions. On a Dynamixel bus (``--teleop.port``) or a CAN bus
  (``--teleop.can``); ``--teleop.id`` is its rig id (its own joint calibration).
- ``ergo_jr_scripted``: motions drawn from a seed (the Ergo Jr's motor primitives, as
  ``ergo explore --strategy rpe`` plays them), for tests and demos without hands or a display.
"""

from __future__ import annotations

from dataclasses import dataclass

from lerobot.teleoperators.config import TeleoperatorConfig

from robot.canopen.bus import DEFAULT_BITRATE
from robot.dynamixel.bus import DEFAULT_BAUD
from robot.spec import CONTROL_RATE_HZ, ERGO_JR_MAX_STEP

# The scripted teleoperator's timing, s: from rest to the motion's first point, then the motion
# (the motor primitive's own duration, 40 points at 40 Hz), back to rest, a pause at rest.
# Guesses: as slow as an episode's return to rest (explore/rigs/episodes.py reset_s, 1 s).
LEAD_S = 0.5
RETURN_S = 1.0
PAUSE_S = 0.5
# The fastest a scripted joint moves, rad/s: half the arm's step bound (0.15 rad per 40 Hz tick,
# 6 rad/s), so that a follower at 20 Hz or more plays the motions unclipped. A motor primitive
# played at its own rate moves up to 0.6 rad a tick (median 0.34, 1000 draws): it is slowed down.
MAX_SPEED = 0.5 * ERGO_JR_MAX_STEP * CONTROL_RATE_HZ


@TeleoperatorConfig.register_subclass("ergo_jr_leader")
@dataclass(kw_only=True)
class ErgoJrLeaderConfig(TeleoperatorConfig):
    """A leader arm on one bus.

    Attributes:
        id: its rig id (required): its joint calibration is ``<root>/<id>/joints.json``, the
            root being ``calibration_dir``, ``ERGO_CALIBRATION_DIR`` or the default folder.
        port, baud, model: a Dynamixel bus (the serial port, bit/s, the servos' model).
        can, bitrate: a CAN bus (python-can ``INTERFACE:CHANNEL``, bit/s).
    """

    port: str | None = None
    baud: int = DEFAULT_BAUD
    model: str = "XL-320"
    can: str | None = None
    bitrate: int = DEFAULT_BITRATE

    def __post_init__(self) -> None:
        if (self.port is None) == (self.can is None):
            raise ValueError(
                "ergo_jr_leader needs one bus: --teleop.port=SERIAL_PORT (Dynamixel) or "
                "--teleop.can=INTERFACE:CHANNEL (CANopen)"
            )
        if not self.id:
            raise ValueError(
                "ergo_jr_leader needs --teleop.id=ID, the rig id its joint calibration is kept "
                "under (lerobot-calibrate --teleop.type=ergo_jr_leader or ergo calibrate joints)"
            )


@TeleoperatorConfig.register_subclass("ergo_jr_scripted")
@dataclass(kw_only=True)
class ErgoJrScriptedConfig(TeleoperatorConfig):
    """Scripted motions: each one goes from rest to a motor primitive drawn from the seed
    (48 parameters uniform in [-1, 1]), plays it, returns to rest and pauses.

    Attributes:
        seed: the motions' seed.
        lead_s, return_s, pause_s: the least time to the motion's start, back to rest, and the
            pause at rest, s.
        max_speed: the fastest any joint moves, rad/s (the motion is slowed down to it).
    """

    seed: int = 0
    lead_s: float = LEAD_S
    return_s: float = RETURN_S
    pause_s: float = PAUSE_S
    max_speed: float = MAX_SPEED

    def __post_init__(self) -> None:
        if not (isinstance(self.max_speed, int | float) and self.max_speed > 0):
            raise ValueError(f"max_speed must be rad/s > 0, got {self.max_speed!r}")
        for key in ("lead_s", "return_s", "pause_s"):
            value = getattr(self, key)
            if not (isinstance(value, int | float) and value > 0):
                raise ValueError(f"{key} must be seconds > 0, got {value!r}")
