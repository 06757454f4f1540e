"""Teleoperators for the Poppy Ergo Jr (docs/lerobot.md): importing this package registers
``ergo_jr_leader`` (a second arm, torque off, read at the loop rate) and ``ergo_jr_scripted``
(motions drawn from a seed, for headless tests and demos), which LeRobot's scripts find by this
distribution's name (``register_third_party_plugins``)."""

from lerobot_teleoperator_ergo_jr.config_ergo_jr_teleop import (
    ErgoJrLeaderConfig,
    ErgoJrScriptedConfig,
)
from lerobot_teleoperator_ergo_jr.leader import ErgoJrLeader
from lerobot_teleoperator_ergo_jr.scripted import ErgoJrScripted

__all__ = ["ErgoJrLeader", "ErgoJrLeaderConfig", "ErgoJrScripted", "ErgoJrScriptedConfig"]
