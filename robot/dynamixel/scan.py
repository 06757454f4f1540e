"""``ergo bus scan --port PORT [--baud B] [--ids ...]``: PING each id, print what answers."""

from __future__ import annotations

import argparse
import contextlib
from collections.abc import Sequence

from plumbing.cli_errors import error
from robot.dynamixel.bus import DEFAULT_BAUD, DynamixelBus, DynamixelError, NoStatusError, PingReply
from robot.dynamixel.control_table import MODELS
from robot.dynamixel.protocol import MAX_SERVO_ID
from robot.errors import BusError
from robot.spec import ergo_jr_spec

ARM_IDS = tuple(ergo_jr_spec().ids)  # m1..m6

# Slack per PING while scanning, s: a missing id costs this long, so it is short (the FTDI
# default latency timer of 16 ms plus a little; guess). 253 ids take about 5 s.
SCAN_LATENCY_S = 0.02


# The ids asked a second time, slowly, when they missed the quick sweep: a servo whose reply
# came late (the emulator of `ergo twin serve` on a loaded machine answered 1 of 6 in a test
# run, 2026-12-02; a USB adapter's latency timer at its worst) is then not reported missing.
# Guess: 0.1 s of slack and 2 retries each, a second at most for the arm's six ids.
SECOND_LOOK_LATENCY_S = 0.1
SECOND_LOOK_RETRIES = 2


def scan(bus: DynamixelBus, ids: list[int], again: Sequence[int] = ()) -> list[PingReply]:
    """PING each id once (no retries), then each id of ``again`` that did not answer once more
    with ``SECOND_LOOK_LATENCY_S`` of slack; the servos that answered, in id order."""
    found: dict[int, PingReply] = {}
    for sid in ids:
        try:
            found[sid] = bus.ping(sid, retries=0)
        except NoStatusError:
            continue
    late = [sid for sid in again if sid in ids and sid not in found]
    if late:
        bus.latency_s = max(bus.latency_s, SECOND_LOOK_LATENCY_S)
        for sid in late:
            with contextlib.suppress(NoStatusError):
                found[sid] = bus.ping(sid, retries=SECOND_LOOK_RETRIES)
    return [found[sid] for sid in sorted(found)]


def format_reply(reply: PingReply) -> str:
    model = MODELS.get(reply.model_number)
    name = model.name if model else "unknown model"
    return f"{reply.id:>3}  {name} (model {reply.model_number})  firmware {reply.firmware}"


def scan_cli(args: argparse.Namespace) -> int:
    """Print one line per servo found; exit 0 if any answered, 1 if none, 2 on a bus error."""
    ids = list(range(MAX_SERVO_ID + 1)) if not args.ids else list(args.ids)
    bad = [i for i in ids if not 0 <= i <= MAX_SERVO_ID]
    if bad:
        return error(f"ids must be in 0..{MAX_SERVO_ID}, got {bad[0]}")
    baud = int(getattr(args, "baud", None) or DEFAULT_BAUD)
    try:
        with DynamixelBus(args.port, baud, retries=0, latency_s=SCAN_LATENCY_S) as bus:
            # the arm's own ids (or the ids asked for) get a second, slower look
            found = scan(bus, ids, again=list(args.ids) if args.ids else list(ARM_IDS))
    except (BusError, DynamixelError) as exc:
        return error(exc)
    if not found:
        print(
            f"no servo answered on {args.port} at {baud} baud "
            f"(check power, wiring and the baud rate)"
        )
        return 1
    print(f" id  model  firmware   ({len(found)} on {args.port} at {baud} baud)")
    for reply in found:
        print(format_reply(reply))
    return 0
