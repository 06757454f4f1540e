"""robot.canopen.bus.can_interfaces: the CAN network interfaces Linux lists (type 280,
``ARPHRD_CAN``), which a failed ``socketcan:CHANNEL`` names instead of a fixed can0."""

from __future__ import annotations

from robot.canopen.bus import ARPHRD_CAN, can_interfaces


def test_only_can_interfaces_are_listed_sorted(tmp_path):
    for name, kind in {"vcan0": ARPHRD_CAN, "lo": "772", "can1": ARPHRD_CAN, "eth0": "1",
                       "odd": "not a number"}.items():  # fmt: skip
        (tmp_path / name).mkdir()
        (tmp_path / name / "type").write_text(f"{kind}\n")
    (tmp_path / "notype").mkdir()  # no type file: left out
    assert can_interfaces(tmp_path) == ["can1", "vcan0"]


def test_no_such_folder_is_no_interface(tmp_path):
    assert can_interfaces(tmp_path / "absent") == []
