"""``ergo bus set-id``: give a servo its bus id (Dynamixel).

Factory XL-320s all answer as id 1 (ROBOTIS e-manual, control table default), so an Ergo Jr is
set up one servo at a time: connect one servo alone, give it its id (m1 -> 1 ... m6 -> 6), then
the next. The ID register is in the EEPROM area, writable only with torque off (e-manual): the
command turns torque off first. Whether the status reply to the write carries the old or the new
id is not relied on: the write may go unanswered, and the new id is confirmed by a PING.
"""

from __future__ import annotations

import argparse
import contextlib

from plumbing.cli_errors import error
from robot.dynamixel.bus import DEFAULT_BAUD, DynamixelBus, DynamixelError, NoStatusError, PingReply
from robot.dynamixel.control_table import MODELS
from robot.dynamixel.protocol import MAX_SERVO_ID
from robot.errors import BusError

# Slack per exchange, s: one servo on a short cable; the FTDI default latency timer of 16 ms
# plus a little (guess, as robot/dynamixel/scan.py).
SET_ID_LATENCY_S = 0.02


class SetIdError(RuntimeError):
    """The id could not be set; the message is one line naming the fix."""


def _ping(bus: DynamixelBus, servo_id: int) -> PingReply | None:
    try:
        return bus.ping(servo_id, retries=1)
    except NoStatusError:
        return None


def set_id(bus: DynamixelBus, old: int, new: int) -> PingReply:
    """Give the servo answering as ``old`` the id ``new``; its PING reply under ``new``.

    Raises:
        SetIdError: no servo answers as ``old``, ``new`` is taken, or the servo does not
            answer as ``new`` afterwards.
    """
    for name, value in (("id", old), ("new id", new)):
        if not 0 <= value <= MAX_SERVO_ID:
            raise SetIdError(f"{name} must be in 0..{MAX_SERVO_ID}, got {value}")
    first = _ping(bus, old)
    if first is None:
        raise SetIdError(
            f"no servo answers as id {old} on {bus.port}: check power and wiring, the baud "
            f"rate (--baud), and that the servo is alone on the bus"
        )
    if new == old:
        return first
    if _ping(bus, new) is not None:
        raise SetIdError(
            f"a servo already answers as id {new} on {bus.port}: connect the servo to set "
            f"alone on the bus"
        )
    model = MODELS.get(first.model_number)
    if model is None:
        raise SetIdError(f"servo {old} is model {first.model_number}, which ergo does not know")
    bus.models[old] = model
    bus.write_register(old, "torque", 0)  # the ID register is EEPROM: torque off first
    # the reply may come from the new id, or none: the PING below decides
    with contextlib.suppress(NoStatusError):
        bus.write_register(old, "id", new)
    after = _ping(bus, new)
    if after is None:
        raise SetIdError(
            f"servo {old} did not answer as id {new} after the write: power-cycle it and run "
            f"`ergo bus scan` to see which id it has"
        )
    return after


def set_id_cli(args: argparse.Namespace) -> int:
    """``ergo bus set-id --port P --id OLD --new-id NEW``: exit 0 when done, 2 otherwise."""
    baud = int(getattr(args, "baud", None) or DEFAULT_BAUD)
    try:
        with DynamixelBus(args.port, baud, retries=1, latency_s=SET_ID_LATENCY_S) as bus:
            reply = set_id(bus, args.id, args.new_id)
    except (SetIdError, BusError, DynamixelError) as exc:
        return error(exc)
    model = MODELS.get(reply.model_number)
    name = model.name if model else f"model {reply.model_number}"
    print(f"servo {args.id} now answers as id {reply.id} ({name}, firmware {reply.firmware})")
    return 0
