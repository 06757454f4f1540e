"""``ErgoJrLeader``: a second Ergo Jr as LeRobot's leader arm (``ergo_jr_leader``).

Its torque is turned off at connect and stays off: a person moves it by hand. Each
``get_action`` reads its joints once over its bus (``robot.Arm.read``), in its own joint
calibration, and gives them as the follower's goal positions, rad: the loop rate is LeRobot's
(``--fps``), one reading per loop. Calibration: ``ergo calibrate joints`` for its rig id, as a
robot's (``lerobot_robot_ergo_jr.bus_arm``).
"""

from __future__ import annotations

import logging
from functools import cached_property
from typing import Any

from lerobot.teleoperators.teleoperator import Teleoperator
from lerobot.utils.errors import DeviceAlreadyConnectedError, DeviceNotConnectedError
from lerobot_robot_ergo_jr.bus_arm import BusArm, OnTheBus
from lerobot_robot_ergo_jr.features import action_features, joints_dict

from lerobot_teleoperator_ergo_jr.config_ergo_jr_teleop import ErgoJrLeaderConfig
from robot.arm import Arm

log = logging.getLogger(__name__)


class ErgoJrLeader(OnTheBus, Teleoperator):
    """A leader Ergo Jr on a Dynamixel or CAN bus (see the module docstring)."""

    config_class = ErgoJrLeaderConfig
    name = "ergo_jr_leader"

    def __init__(self, config: ErgoJrLeaderConfig) -> None:
        super().__init__(config)
        self.config = config
        self.arm: Arm | None = None

    def bus_arm(self) -> BusArm:
        c = self.config
        if c.port is not None:
            return BusArm("dynamixel", c.port, c.baud, str(c.id), c.calibration_dir, model=c.model)
        assert c.can is not None  # the config asks for one bus
        return BusArm("canopen", c.can, c.bitrate, str(c.id), c.calibration_dir)

    @cached_property
    def action_features(self) -> dict[str, type]:
        return action_features()

    @cached_property
    def feedback_features(self) -> dict[str, type]:
        return {}

    @property
    def is_connected(self) -> bool:
        return self.arm is not None and self.arm.is_connected

    def connect(self, calibrate: bool = True) -> None:
        if self.is_connected:
            raise DeviceAlreadyConnectedError(f"{self} is already connected")
        if calibrate and not self.is_calibrated:
            log.info("%s has no joint calibration: calibrating first", self)
            self.calibrate()
        self._open()

    def _open(self) -> None:
        arm, _ = self.bus_arm().build()
        arm.connect()
        try:
            arm.set_torque(False)  # limp: moved by hand
        except BaseException:
            arm.disconnect(torque_off=True)
            raise
        self.arm = arm
        log.info("%s connected, torque off", self)

    def configure(self) -> None:
        """Nothing to set (torque goes off at connect)."""

    def get_action(self) -> dict[str, float]:
        """The leader's joints now, rad."""
        if self.arm is None or not self.arm.is_connected:
            raise DeviceNotConnectedError(f"{self} is not connected")
        return joints_dict(self.arm.read().positions)

    def send_feedback(self, feedback: dict[str, Any]) -> None:
        """A limp leader takes no feedback (``feedback_features`` is empty)."""

    def disconnect(self) -> None:
        """Torque off (it is already) and close. Does nothing when not connected."""
        arm, self.arm = self.arm, None
        if arm is not None:
            arm.disconnect(torque_off=True)
