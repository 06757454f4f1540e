"""Dynamixel Protocol 2.0 over a serial port: the codec (``protocol``), control tables as data
(``control_table``), the bus with retries and typed errors (``bus``) and ``DynamixelArm``
(``arm``). Only ``protocol`` and ``control_table`` are imported here: they are pure, so the
emulator in ``sim/`` can use them without pyserial."""

from robot.dynamixel.control_table import MODELS, Model, Register, model_by_name
from robot.dynamixel.protocol import (
    BROADCAST_ID,
    CorruptFrame,
    Decoder,
    Instruction,
    InstructionPacket,
    StatusError,
    StatusPacket,
    crc16,
)

__all__ = [
    "BROADCAST_ID",
    "MODELS",
    "CorruptFrame",
    "Decoder",
    "Instruction",
    "InstructionPacket",
    "Model",
    "Register",
    "StatusError",
    "StatusPacket",
    "crc16",
    "model_by_name",
]
