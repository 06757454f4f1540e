"""The physical rigs' options (``dynamixel``, ``canopen``): refused in one line when missing or
wrong, and the rig built unconnected (tests/sim/dynamixel/test_emulator.py runs the dynamixel
rig against the emulated arm and camera)."""

from __future__ import annotations

import pytest

from explore.rigs.rig import RigConfig, RigError, make_rig


def test_rig_needs_a_port() -> None:
    with pytest.raises(RigError, match=r"options\.port"):
        make_rig(RigConfig(name="dynamixel", rig_id="bench", options={}))


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({}, "needs option can"),
        ({"can": "nope"}, "expected INTERFACE:CHANNEL"),
        ({"can": "virtual:x", "node_ids": [1, 2]}, "needs 6 values"),
        ({"can": "virtual:x", "port": "/dev/ttyUSB0"}, "option port is unknown; known: "),
        ({"can": "virtual:x", "camera": 1.5}, "camera must be"),
        ({"can": "virtual:x", "eds": "/nonexistent/drive.eds"}, "EDS file not found"),
    ],
)
def test_rig_options_errors(options, message) -> None:
    with pytest.raises(RigError, match=message):
        make_rig(RigConfig("canopen", "bench", options=options))


def test_rig_builds_unconnected() -> None:
    rig = make_rig(
        RigConfig(
            "canopen",
            "bench",
            options={"can": "slcan:/dev/pts/99", "camera": "0", "bitrate": 500000},
        )
    )
    assert type(rig.sensor).__name__ == "CameraSensor" and not rig.arm.is_connected
    assert str(rig.arm.bus_spec) == "slcan:/dev/pts/99" and rig.arm.bus_spec.bitrate == 500000
    assert type(rig.camera).__name__ == "OpenCVCamera"
    assert type(rig.clock).__name__ == "RealClock"


def test_on_crash_is_limp_unless_the_user_says_hold():
    from explore.options import BadOption
    from explore.rigs.dynamixel import Options

    assert Options().on_crash == "limp" and Options(on_crash="hold").on_crash == "hold"
    with pytest.raises(BadOption, match="on_crash must be one of limp, hold"):
        Options(on_crash="stiff")
