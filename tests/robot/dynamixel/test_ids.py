"""``ergo bus set-id``: a factory servo (id 1) gets its id, over the emulator's packet logic."""

from __future__ import annotations

import pytest

from robot.dynamixel.bus import DynamixelBus
from robot.dynamixel.ids import SetIdError, set_id
from sim.dynamixel.emulator import DynamixelEmulator, EmulatedSerial


def bus_of(*ids: int) -> tuple[DynamixelBus, DynamixelEmulator]:
    emulator = DynamixelEmulator(None, ids=ids)
    bus = DynamixelBus(
        "fake", retries=1, latency_s=0.005, return_delay_s=0.0,
        connection=EmulatedSerial(emulator, echo=True),
    )  # fmt: skip
    return bus, emulator


def test_a_factory_servo_gets_its_id_and_keeps_it() -> None:
    bus, emulator = bus_of(1)
    emulator.servos[1].poke("torque", 1)  # powered: the ID register is locked until torque off
    reply = set_id(bus, 1, 4)
    assert reply.id == 4
    assert sorted(emulator.servos) == [4]
    assert emulator.servos[4].peek("id") == 4 and not emulator.servos[4].torque
    assert bus.ping(4).id == 4


@pytest.mark.parametrize(
    ("ids", "old", "new", "message"),
    [
        ((2,), 1, 3, "no servo answers as id 1"),
        ((1, 3), 1, 3, "a servo already answers as id 3"),
        ((1,), 1, 300, "new id must be in 0..252"),
    ],
)
def test_what_cannot_be_done_is_one_line(ids: tuple, old: int, new: int, message: str) -> None:
    bus, emulator = bus_of(*ids)
    with pytest.raises(SetIdError, match=message) as info:
        set_id(bus, old, new)
    assert "\n" not in str(info.value)
    assert sorted(emulator.servos) == sorted(ids)  # nothing was written
