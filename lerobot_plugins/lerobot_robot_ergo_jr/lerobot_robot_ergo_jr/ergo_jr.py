"""The Ergo Jr as LeRobot robots: ``ErgoJrDynamixel``, ``ErgoJrCanopen`` and ``ErgoJrTwin``.

Each wraps the project's ``robot.Arm`` (``DynamixelArm``, ``CanArm``, ``SimArm``), so that the
arm's own safety holds under LeRobot's scripts:

- every action goes through ``Arm.command``: clamped to the joint limits (narrowed by the rig's
  joint calibration) and to ``max_relative_target`` from the previous command;
- ``disconnect`` turns torque off (LeRobot's scripts call it on exit, on an exception and after
  Ctrl-C), and so does the garbage collector's last call (LeRobot's ``Robot.__del__``);
- while connected, SIGINT and SIGTERM turn torque off at once, before the script's own handling
  (``robot.signals.torque_off_on_signals``), and on a serial bus a guardian process cuts torque if
  this process dies without doing so (``robot.torque_guardian``, ``on_crash``).

Observation: the joints read (``m1.pos`` .. ``m6.pos``, rad), the overhead frame (``overhead``,
RGB) and LeRobot's own cameras, if any. Action: the joints' goal positions, rad
(``lerobot_robot_ergo_jr.features``).
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from contextlib import ExitStack
from functools import cached_property
from typing import Any

import numpy as np
from lerobot.cameras.utils import make_cameras_from_configs
from lerobot.robots import Robot
from lerobot.utils.errors import DeviceAlreadyConnectedError, DeviceNotConnectedError

from lerobot_robot_ergo_jr.bus_arm import BusArm, OnTheBus
from lerobot_robot_ergo_jr.config_ergo_jr import (
    ErgoJrBaseConfig,
    ErgoJrBusConfig,
    ErgoJrCanopenConfig,
    ErgoJrDynamixelConfig,
    ErgoJrTwinConfig,
)
from lerobot_robot_ergo_jr.features import (
    IMAGE_KEY,
    ROBOT_TYPE,
    action_features,
    joints_dict,
    joints_vector,
    observation_features,
    rgb_square,
)
from lerobot_robot_ergo_jr.latest_frame import LatestFrame
from robot.arm import Arm
from robot.signals import torque_off_on_signals
from vision.camera import Camera

log = logging.getLogger(__name__)


class ErgoJrRobot(Robot):
    """What the three robots share (see the module docstring); a subclass builds the arm and
    its overhead camera (``_build``) and says how its frame is read (``_frame_reader``)."""

    config_class = ErgoJrBaseConfig
    name = ROBOT_TYPE

    def __init__(self, config: ErgoJrBaseConfig) -> None:
        super().__init__(config)
        self.config = config
        self.cameras = make_cameras_from_configs(config.cameras)
        self.arm: Arm | None = None
        self.overhead: Camera | None = None
        self._frames: Callable[[], np.ndarray] | None = None  # the overhead frame now
        self._stack: ExitStack | None = None

    # ---- what it observes and takes -------------------------------------------------------
    @property
    def _has_overhead(self) -> bool:
        return bool(self.config.camera)  # type: ignore[attr-defined]

    @cached_property
    def observation_features(self) -> dict[str, Any]:
        side = self.config.image_side if self._has_overhead else None
        out: dict[str, Any] = observation_features(side)
        for key, cam in self.config.cameras.items():
            out[key] = (cam.height, cam.width, 3)
        return out

    @cached_property
    def action_features(self) -> dict[str, type]:
        return action_features()

    # ---- lifecycle -------------------------------------------------------------------------
    @property
    def is_connected(self) -> bool:
        return self.arm is not None and self.arm.is_connected

    def connect(self, calibrate: bool = True) -> None:
        """Calibrate first if asked and the rig has no calibration, then open the arm (torque
        on, holding its pose) and the cameras."""
        if self.is_connected:
            raise DeviceAlreadyConnectedError(f"{self} is already connected")
        if calibrate and not self.is_calibrated:
            log.info("%s has no joint calibration: calibrating first", self)
            self.calibrate()
        self._open()

    def _open(self) -> None:
        arm, overhead = self._build()
        stack = ExitStack()
        try:
            stack.callback(self._close_cameras)
            arm.connect()
            stack.callback(arm.disconnect, True)  # torque off, then close: unwound last
            self._started(arm, stack)
            stack.enter_context(torque_off_on_signals(arm))  # left first: then torque off
            self.arm, self.overhead = arm, overhead
            if overhead is not None:
                overhead.connect()
                self._frames = self._frame_reader(overhead, stack)
            for cam in self.cameras.values():
                cam.connect()
            arm.set_torque(True)  # holding the measured pose (robot.arm.Arm.set_torque)
        except BaseException:
            self.arm, self._frames = None, None
            stack.close()
            raise
        self._stack = stack
        log.info("%s connected", self)

    def _started(self, arm: Arm, stack: ExitStack) -> None:
        """What runs beside the connected arm, its stop pushed on ``stack`` (nothing here)."""

    def _close_cameras(self) -> None:
        for cam in [self.overhead, *self.cameras.values()]:
            if cam is not None and cam.is_connected:
                try:
                    cam.disconnect()
                except Exception as exc:  # a camera must not keep the arm's torque on
                    log.warning("%s: closing a camera: %s", self, exc)

    def disconnect(self) -> None:
        """Torque off and close the arm, then the cameras. Does nothing when not connected (a
        script's ``finally`` may call it after a failed connect or calibration)."""
        stack, self._stack = self._stack, None
        self.arm, self._frames = None, None
        if stack is not None:
            stack.close()
            log.info("%s disconnected (torque off)", self)

    def configure(self) -> None:
        """Nothing to set: the arm's settings are the rig's (``explore/rigs/``)."""

    # ---- I/O -------------------------------------------------------------------------------
    def _require(self) -> Arm:
        if self.arm is None or not self.arm.is_connected:
            raise DeviceNotConnectedError(f"{self} is not connected")
        return self.arm

    def _positions(self, arm: Arm) -> np.ndarray:
        """The joints now, shape (6,), rad."""
        return arm.read().positions

    def get_observation(self) -> dict[str, Any]:
        arm = self._require()
        obs: dict[str, Any] = joints_dict(self._positions(arm))
        if self._frames is not None:
            obs[IMAGE_KEY] = self._frames()
        for key, cam in self.cameras.items():
            obs[key] = cam.async_read()
        return obs

    def _frame_reader(self, camera: Camera, stack: ExitStack) -> Callable[[], np.ndarray]:
        """() -> the overhead frame now, (side, side, 3) RGB uint8: a live camera's newest
        frame (``LatestFrame``, its thread stopped with the rest on ``stack``)."""
        side = self.config.image_side
        frames = LatestFrame(camera, lambda image: rgb_square(image, side))
        stack.callback(frames.stop)
        return frames.get

    def send_action(self, action: dict[str, Any]) -> dict[str, float]:
        """Send the goal positions, clamped by the arm; returns what was sent, rad."""
        arm = self._require()
        return joints_dict(arm.command(joints_vector(action)))

    # ---- for subclasses --------------------------------------------------------------------
    def _build(self) -> tuple[Arm, Camera | None]:
        raise NotImplementedError


class ErgoJrBusRobot(OnTheBus, ErgoJrRobot):
    """An arm on a bus; its joint calibration is the rig's file (``bus_arm``, ``OnTheBus``)."""

    config: ErgoJrBusConfig

    def _build(self) -> tuple[Arm, Camera | None]:
        arm, camera = self.bus_arm().build(self.config.max_relative_target)
        return arm, camera


class ErgoJrDynamixel(ErgoJrBusRobot):
    """The arm's XL-320 servos on a Dynamixel bus (``ergo_jr_dynamixel``)."""

    config_class = ErgoJrDynamixelConfig
    config: ErgoJrDynamixelConfig

    def bus_arm(self) -> BusArm:
        c = self.config
        return BusArm(
            "dynamixel", c.port, c.baud, str(c.id), c.calibration_dir, model=c.model,
            on_crash=c.on_crash, camera=c.camera,
        )  # fmt: skip


class ErgoJrCanopen(ErgoJrBusRobot):
    """The arm's CiA 402 drives on a CAN bus (``ergo_jr_canopen``)."""

    config_class = ErgoJrCanopenConfig
    config: ErgoJrCanopenConfig

    def bus_arm(self) -> BusArm:
        c = self.config
        return BusArm(
            "canopen", c.can, c.bitrate, str(c.id), c.calibration_dir, on_crash=c.on_crash,
            camera=c.camera,
        )  # fmt: skip


class ErgoJrTwin(ErgoJrRobot):
    """The MuJoCo twin in this process (``ergo_jr_twin``): its physics follows the wall clock
    (``sim.realtime.RealtimeLoop``, caught up before each reading), its overhead camera rendered
    at ``image_side``. The twin has no servo mounting to measure: it needs no calibration."""

    config_class = ErgoJrTwinConfig
    config: ErgoJrTwinConfig

    def __init__(self, config: ErgoJrTwinConfig) -> None:
        super().__init__(config)
        self.twin: Any = None

    @property
    def is_calibrated(self) -> bool:
        return True

    def calibrate(self) -> None:
        print(
            f"{self}: the twin's joint angles are its servos' (no mounting to measure): nothing "
            "to calibrate"
        )

    def _build(self) -> tuple[Arm, Camera | None]:
        import dataclasses

        from explore.rigs.rig import RigConfig, make_rig

        side = self.config.image_side
        rig = make_rig(RigConfig("sim", str(self.config.id), {"render_size": [side, side]}))
        assert rig.arm is not None and rig.sensor is not None
        rig.arm.spec = dataclasses.replace(rig.arm.spec, max_step=self.config.max_relative_target)
        self.twin = rig.sensor.twin  # type: ignore[attr-defined]  # the twin rig's TwinSensor
        return rig.arm, rig.camera if self.config.camera else None

    def _started(self, arm: Arm, stack: ExitStack) -> None:
        from sim.realtime import RealtimeLoop

        loop = RealtimeLoop(self.twin)
        loop.start()
        stack.callback(loop.stop)

    def _positions(self, arm: Arm) -> np.ndarray:
        with self.twin.lock:
            self.twin.catch_up()
            return arm.read().positions

    def _frame_reader(self, camera: Camera, stack: ExitStack) -> Callable[[], np.ndarray]:
        """() -> the overhead camera rendered now at (side, side), RGB."""
        return lambda: self.render(camera)

    def render(self, camera: Camera) -> np.ndarray:
        """The twin's overhead square at ``image_side``, RGB uint8, physics caught up first."""
        with self.twin.lock:
            self.twin.catch_up()
        side = self.config.image_side
        return np.ascontiguousarray(camera.read_square(side).image[..., ::-1])  # type: ignore[attr-defined]
