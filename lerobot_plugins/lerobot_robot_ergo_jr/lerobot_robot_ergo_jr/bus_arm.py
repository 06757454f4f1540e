"""An Ergo Jr on a bus, as the robots and the leader arm get it: built by the project's own rigs
(``explore/rigs/dynamixel.py``, ``canopen.py``), so that the joint calibration applies as in
``ergo explore`` (offsets, directions, the limits narrowed to the calibrated ones:
``explore/rigs/hardware.py`` ``joint_setup``), and calibrated by the project's own command.

The one source of truth of a rig's joints is its calibration file, ``<root>/<rig_id>/joints.json``
(``robot/calibration_files.py``). ``calibrate`` runs ``ergo calibrate joints --rig-id ID`` with
the same bus flags, in this process: the same prompts, the same checks and the same file, so that
``lerobot-calibrate`` and ``ergo calibrate joints`` write one file and every tool reads it.
"""

from __future__ import annotations

import dataclasses
import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

from explore.rigs.rig import RigConfig, make_rig
from robot.arm import Arm
from robot.calibration_files import RigCalibration
from vision.camera import Camera

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class BusArm:
    """Which arm, on which bus, calibrated where.

    Attributes:
        kind: ``dynamixel`` or ``canopen``.
        where: the serial port, or the python-can ``INTERFACE:CHANNEL``.
        rate: baud rate or CAN bitrate, bit/s.
        rig_id: the rig id (its calibration folder).
        root: the calibration root (None: ``ERGO_CALIBRATION_DIR`` or the default folder).
        model: the Dynamixel servos' model (ignored on CANopen).
        on_crash: ``limp`` or ``hold`` (``robot.torque_guardian``).
        camera: the overhead camera's source (None: none).
    """

    kind: Literal["dynamixel", "canopen"]
    where: str
    rate: int
    rig_id: str
    root: Path | None = None
    model: str = "XL-320"
    on_crash: str = "limp"
    camera: str | None = None

    @property
    def calibration(self) -> RigCalibration:
        """The rig's calibration files (they may not exist)."""
        return RigCalibration.find(self.rig_id, self.root)

    @property
    def is_calibrated(self) -> bool:
        """Whether the rig has a joint calibration file (its content is checked when the arm is
        built: a damaged file is refused there, in one line)."""
        joints = self.calibration.joints
        return joints is not None and joints.is_file()

    def bus_flags(self) -> list[str]:
        """The ``ergo`` flags that name this bus."""
        if self.kind == "dynamixel":
            return ["--port", self.where, "--baud", str(self.rate), "--model", self.model]
        return ["--can", self.where, "--bitrate", str(self.rate)]

    def rig_options(self) -> dict[str, Any]:
        """The rig's options (``explore/rigs/dynamixel.py`` / ``canopen.py``)."""
        out: dict[str, Any] = {"on_crash": self.on_crash}
        if self.kind == "dynamixel":
            out.update(port=self.where, baud=self.rate, model=self.model)
        else:
            out.update(can=self.where, bitrate=self.rate)
        if self.camera is not None:
            out["camera"] = self.camera
        return out

    def build(self, max_step: float | None = None) -> tuple[Arm, Camera | None]:
        """The arm (not connected) with the rig's joint calibration, and the overhead camera (not
        connected; None without one). ``max_step``: the step bound, rad (default the spec's).
        A ``explore.rigs.rig.RigError`` (one line) for a damaged calibration file or bad
        options."""
        config = RigConfig(self.kind, self.rig_id, self.rig_options(), calibration=self.calibration)
        rig = make_rig(config)
        arm = rig.arm
        assert arm is not None  # a bus rig has an arm
        if max_step is not None:
            arm.spec = dataclasses.replace(arm.spec, max_step=max_step)
        return arm, rig.camera if self.camera is not None else None

    def calibrate(self) -> None:
        """``ergo calibrate joints --rig-id ID BUS`` in this process (its prompts on this
        terminal); raises ``SystemExit`` with its exit code when it fails or is interrupted
        (it has printed its one ``ergo: error:`` line, and saved nothing)."""
        from explore.cli import main

        argv = ["calibrate", "joints", "--rig-id", self.rig_id, *self.bus_flags()]
        if self.root is not None:
            argv += ["--dir", str(self.root)]
        rc = main(argv)
        if rc != 0:
            raise SystemExit(rc)


class OnTheBus:
    """What a LeRobot device on a bus shares, robot or leader: its joint calibration is the rig's
    file (``bus_arm``), made by ``ergo calibrate joints`` with the device closed meanwhile
    (torque off) and opened again after if it was open. The class it is mixed into gives
    ``bus_arm``, ``is_connected``, ``disconnect`` and ``_open``."""

    def bus_arm(self) -> BusArm:
        raise NotImplementedError

    @property
    def is_calibrated(self) -> bool:
        return self.bus_arm().is_calibrated

    def calibrate(self) -> None:
        """``ergo calibrate joints`` for this rig id and bus (``BusArm.calibrate``)."""
        reopen = self.is_connected  # type: ignore[attr-defined]
        self.disconnect()  # type: ignore[attr-defined]
        self.bus_arm().calibrate()
        if reopen:
            self._open()  # type: ignore[attr-defined]
