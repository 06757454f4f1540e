"""The Dynamixel bus with late replies: a status packet that comes after its call gave up is
recognised and set aside, never taken for a later call's answer nor counted as a CRC error,
and the timeout follows the latency the bus measures, within its bound.

Runs over the emulator's in-process serial port, whose replies keep their order on the wire
(a late one delays those behind it) and whose ``reset_input_buffer`` drops only what has
arrived, as ``tcflush`` does."""

from __future__ import annotations

import time

import pytest

from robot.dynamixel.bus import MAX_LATENCY_S, DynamixelBus, NoStatusError
from sim.dynamixel.emulator import DynamixelEmulator, EmulatedSerial, FaultConfig

FLOOR_S = 0.005  # the least slack of these buses: the fake answers in-process
GOAL = 100  # goal_position written to servo i is GOAL + i: no other 2-byte register holds it
MODEL = 350  # the XL-320's model number


def bus_and_emulator(retries: int = 2, echo: bool = True) -> tuple[DynamixelBus, DynamixelEmulator]:
    emulator = DynamixelEmulator(None)
    bus = DynamixelBus(
        "fake", retries=retries, latency_s=FLOOR_S, return_delay_s=0.0,
        connection=EmulatedSerial(emulator, echo=echo),
    )  # fmt: skip
    for i in range(1, 7):
        bus.write_register(i, "goal_position", GOAL + i)
    return bus, emulator


def test_a_late_reply_is_set_aside_and_the_next_call_gets_its_own_answer() -> None:
    bus, emulator = bus_and_emulator(retries=0)
    emulator.faults = FaultConfig(late_rate=1.0, late_s=0.2)  # far past the 5 ms slack
    with pytest.raises(NoStatusError):
        bus.read_register(1, "goal_position")
    emulator.faults = FaultConfig()
    bus.retries = 6  # the model number's reply waits behind the late one, on the same wire
    # the late goal reply (2 bytes from servo 1) arrives during this call: the old bus took it
    # for the model number's answer
    assert bus.read_register(1, "model_number") == MODEL
    assert bus.read_register(1, "goal_position") == GOAL + 1
    assert bus.counters.late_replies >= 1  # and the model number retries' second answers
    assert bus.counters.crc_errors == 0
    assert bus.latency.largest == pytest.approx(0.2, abs=0.1)  # the late one measured


def test_late_and_lost_replies_never_give_a_wrong_value_nor_a_crc_error() -> None:
    bus, emulator = bus_and_emulator(retries=2)
    emulator.faults = FaultConfig(late_rate=0.05, late_s=0.06, drop_rate=0.03, seed=3)
    failed = 0
    for k in range(120):
        sid = 1 + k % 6
        name, want = ("model_number", MODEL) if k % 2 else ("goal_position", GOAL + sid)
        try:
            assert bus.read_register(sid, name) == want, (k, name)
        except NoStatusError:
            failed += 1  # allowed: what must never happen is a wrong value
        if k % 3:
            continue
        try:
            data = bus.sync_read(30, 2, [1, 2, 3, 4, 5, 6])  # goal positions, in one packet
        except NoStatusError:
            failed += 1
            continue
        assert {i: int.from_bytes(v, "little") for i, v in data.items()} == {
            i: GOAL + i for i in range(1, 7)
        }
    assert bus.counters.crc_errors == 0
    assert bus.counters.late_replies > 0
    assert failed < 20, bus.counters


def test_the_timeout_grows_to_the_latency_measured_and_comes_back_down() -> None:
    bus, emulator = bus_and_emulator(retries=2)
    emulator.faults = FaultConfig(extra_delay_s=0.03)  # every reply 30 ms late
    for _ in range(30):
        assert bus.read_register(2, "model_number") == MODEL
    assert bus.latency.slack > 0.03  # learnt
    retries = bus.counters.retries
    for _ in range(20):
        assert bus.read_register(3, "goal_position") == GOAL + 3
    assert bus.counters.retries == retries  # no more timeouts once learnt
    emulator.faults = FaultConfig()
    for _ in range(60):
        bus.read_register(4, "model_number")
    # the estimate follows the latency down (what is left is the host's own lateness)
    assert bus.latency.mean < 0.015
    assert bus.latency.slack >= FLOOR_S
    assert bus.counters.crc_errors == 0


def test_a_reply_later_than_the_bound_is_lost_and_the_call_gives_up_in_bounded_time() -> None:
    bus, emulator = bus_and_emulator(retries=2)
    for _ in range(10):
        bus.read_register(5, "model_number")  # a fast bus: the slack is at its floor
    emulator.faults = FaultConfig(extra_delay_s=2.0)
    started = time.monotonic()
    with pytest.raises(NoStatusError):
        bus.read_register(5, "model_number")
    # three attempts of 5, 20 and 80 ms slack (x4 a retry), well under the bound each
    assert time.monotonic() - started < 3 * MAX_LATENCY_S
    assert bus.latency.slack <= MAX_LATENCY_S
    assert bus.latency.slack_of_attempt(10) == MAX_LATENCY_S  # backoff capped


def test_a_slack_asked_for_is_kept_even_above_the_bound() -> None:
    bus = DynamixelBus("x", latency_s=0.8)
    assert bus.latency.slack == bus.latency.slack_of_attempt(3) == 0.8
    bus.latency_s = 0.01
    assert bus.latency.slack == 0.01
