"""EMCY error codes named per CiA 301 (classes, communication) and CiA 402-2 (the drive's):
the common codes by their own name, every other code of a defined class by its group or
class, never "unknown error"."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from robot.canopen import emcy


@pytest.mark.parametrize(
    ("code", "name"),
    [
        (0x7310, "sensor: speed"),
        (0x5530, "data storage: non-volatile data memory"),
        (0x7320, "sensor: position"),
        (0x7121, "motor blocked"),
        (0x5510, "data storage: working memory"),
        (0x6320, "parameter error"),
        (0x3130, "phase failure"),
        (0x8611, "following error"),
        (0x8130, "life guard or heartbeat error"),
    ],
)
def test_common_codes_have_their_own_name(code, name):
    """Was: 0x7310 and 0x5530 printed as "unknown error" (classes 0x5xxx and 0x7xxx matched
    with the mask 0xFF00)."""
    assert emcy.describe_code(code) == name


@pytest.mark.parametrize(
    ("code", "name"),
    [
        (0x7399, "sensor"),  # a code of group 0x73xx not named on its own
        (0x55FF, "data storage"),
        (0x5FFF, "device hardware"),  # no group: the class
        (0x7FFF, "additional modules"),
        (0x8A12, "control"),
        (0xFF42, "device specific"),
    ],
)
def test_other_codes_are_named_by_their_group_or_class(code, name):
    assert emcy.describe_code(code) == name


@given(st.integers(0x2000, 0x8FFF))
def test_no_code_of_a_defined_class_is_unknown(code):
    """CiA 301 defines the classes 0x2xxx to 0x8xxx whole (current, voltage, temperature,
    device hardware, device software, additional modules, monitoring)."""
    assert emcy.describe_code(code) != "unknown error"


def test_reset_and_codes_outside_the_classes():
    assert emcy.describe_code(0x0000) == "error reset / no error"
    assert emcy.describe_code(0x0123) == "unknown error"
    assert emcy.describe_code(0xA000) == "unknown error"
