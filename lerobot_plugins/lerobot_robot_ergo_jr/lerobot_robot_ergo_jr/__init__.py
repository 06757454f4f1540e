"""The Poppy Ergo Jr as LeRobot robots (docs/lerobot.md): importing this package registers the
robot types ``ergo_jr_dynamixel``, ``ergo_jr_canopen`` and ``ergo_jr_twin``, which LeRobot's
scripts find by this distribution's name (``register_third_party_plugins``)."""

from lerobot_robot_ergo_jr.config_ergo_jr import (
    ErgoJrCanopenConfig,
    ErgoJrDynamixelConfig,
    ErgoJrTwinConfig,
)
from lerobot_robot_ergo_jr.ergo_jr import ErgoJrCanopen, ErgoJrDynamixel, ErgoJrTwin

__all__ = [
    "ErgoJrCanopen",
    "ErgoJrCanopenConfig",
    "ErgoJrDynamixel",
    "ErgoJrDynamixelConfig",
    "ErgoJrTwin",
    "ErgoJrTwinConfig",
]
