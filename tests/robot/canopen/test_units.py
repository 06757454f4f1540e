"""Pure helpers of the CANopen backend: bus specs, units, EMCY decoding, the rig's options."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from robot.canopen import emcy
from robot.canopen.bus import CanBusError, CanBusSpec, open_bus, parse_can_spec
from robot.canopen.units import JointScaling, UnitsError
from robot.errors import BusError


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("socketcan:can0", CanBusSpec("socketcan", "can0", None)),
        ("slcan:/dev/ttyACM0", CanBusSpec("slcan", "/dev/ttyACM0", 1_000_000)),
        ("virtual:test", CanBusSpec("virtual", "test", None)),
        ("slcan:COM3@115200", CanBusSpec("slcan", "COM3@115200", 1_000_000)),
    ],
)
def test_parse_can_spec(text: str, expected: CanBusSpec) -> None:
    assert parse_can_spec(text) == expected


def test_bitrate_kept_only_where_the_interface_takes_it() -> None:
    assert parse_can_spec("slcan:/dev/ttyACM0", 500_000).bitrate == 500_000
    assert parse_can_spec("socketcan:can0", 500_000).bitrate is None


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("can0", "expected INTERFACE:CHANNEL"),
        (":can0", "expected INTERFACE:CHANNEL"),
        ("socketcan:", "expected INTERFACE:CHANNEL"),
        ("sockcan:can0", "unknown CAN interface 'sockcan'"),
        ("udp_multicast:224.0.0.1", "runs over the network"),
    ],
)
def test_bad_specs_are_one_line_bus_errors(text: str, message: str) -> None:
    with pytest.raises(CanBusError, match=message) as info:
        parse_can_spec(text)
    assert isinstance(info.value, BusError) and "\n" not in str(info.value)


def test_bad_bitrates() -> None:
    with pytest.raises(CanBusError, match="SLCAN cannot run at 300000"):
        parse_can_spec("slcan:/dev/ttyACM0", 300_000)
    with pytest.raises(CanBusError, match="positive integer"):
        parse_can_spec("pcan:PCAN_USBBUS1", -5)


def test_missing_adapter_is_a_one_line_bus_error() -> None:
    with pytest.raises(CanBusError, match="no such device /dev/ttyACM9") as info:
        open_bus("slcan:/dev/ttyACM9")
    assert "\n" not in str(info.value)


def test_virtual_bus_opens() -> None:
    bus = open_bus("virtual:units-test")
    bus.shutdown()


@given(
    q=st.lists(st.floats(-3.0, 3.0), min_size=6, max_size=6),
    cpr=st.sampled_from([4096, 65536, 131072, 10000]),
    dirs=st.lists(st.sampled_from([-1.0, 1.0]), min_size=6, max_size=6),
    offs=st.lists(st.floats(-1.0, 1.0), min_size=6, max_size=6),
)
def test_units_round_trip_within_one_increment(q, cpr, dirs, offs) -> None:
    s = JointScaling(np.full(6, cpr), np.array(dirs), np.array(offs))
    back = s.to_rad(s.to_counts(np.array(q)))
    assert np.all(np.abs(back - np.array(q)) <= math.tau / cpr / 2 + 1e-12)


def test_units_direction_offset_and_limits() -> None:
    s = JointScaling(np.full(2, 4096.0), np.array([1.0, -1.0]), np.array([0.0, 0.5]))
    assert s.to_counts(np.array([math.pi, 0.5])).tolist() == [2048, 0]
    assert s.to_counts(np.array([0.0, 0.5 + math.pi / 2])).tolist() == [0, -1024]
    lo, hi = s.limits_to_counts(np.array([-1.0, -1.0]), np.array([1.0, 1.0]))
    assert np.all(lo < hi)


@pytest.mark.parametrize(
    ("kw", "message"),
    [
        ({"counts_per_rev": np.zeros(6)}, "must be positive"),
        ({"directions": np.full(6, 2.0)}, r"\+1 or -1"),
        ({"offsets": np.zeros(5)}, "sizes differ"),
    ],
)
def test_bad_scalings(kw, message) -> None:
    args = {"counts_per_rev": np.ones(6), "directions": np.ones(6), "offsets": np.zeros(6)}
    with pytest.raises(UnitsError, match=message):
        JointScaling(**{**args, **kw})


def test_position_beyond_32_bits() -> None:
    s = JointScaling(np.full(1, 2.0**31), np.ones(1), np.zeros(1))
    with pytest.raises(UnitsError, match="32-bit"):
        s.to_counts(np.array([7.0]))


def test_emcy_descriptions() -> None:
    assert emcy.describe(0x8611, 0x21) == (
        "EMCY 0x8611 following error (error register 0x21: generic, device profile)"
    )
    assert emcy.describe_code(0x4299) == "device temperature"  # its group, 0x42xx
    assert emcy.describe_code(0x0123) == "unknown error"
    assert emcy.unpack(emcy.pack(0x8611, 0x21)) == (0x8611, 0x21, b"\0" * 5)
