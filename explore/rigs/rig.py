"""A ``Rig`` is an Arm + a Camera + a Clock + a ball sensor + a motor primitive, or a simulated
scene that plays whole episodes itself (ArmBalls), and the scene the learner and the metric see
(``scene``). The exploration loop asks it for its episode player (``Rig.episodes``), its scene's
state after an episode (``snapshot``) and to restore it on resume (``restore``), and never
asks which rig it is.

Rigs are built by name from ``RIGS``, a table of name -> module imported lazily
(``plumbing.registry.LazyTable``), so a user without a CAN adapter library never imports it. Each
rig module defines its typed ``Options`` (a dataclass: unknown keys and wrong types are refused
by ``explore.options.parse_options``), ``make_rig(config, options) -> Rig``, which returns
an unconnected rig, ``PHYSICAL`` (a real arm, or nothing physical attached) and
``scene(config, options) -> explore.learner.scene.Scene`` (cheap: reports ask for it without
building the rig).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import Any

import numpy as np

from explore.learner.dmp import MotorPrimitive
from explore.learner.scene import Scene
from explore.options import OptionsError, parse_options
from explore.rigs.ball import NO_STATE, BallSensor
from explore.rigs.clock import Clock
from explore.rigs.episodes import EpisodeConfig, EpisodePlayer
from explore.rigs.errors import RigError
from explore.rigs.motor import ergo_jr_dmp
from plumbing.registry import LazyTable
from robot.arm import Arm
from robot.calibration_files import CalibrationError, RigCalibration
from vision.camera import Camera

NO_JOINT_CALIBRATION = "none"  # rig option joint_calibration: use the options, read no file

# name -> the module with its ``Options``, ``make_rig`` and ``PHYSICAL`` (whether a real arm is
# attached, which only the host that has it can run)
RIGS = LazyTable(
    "rig",
    {
        "sim": "explore.rigs.sim",
        "dynamixel": "explore.rigs.dynamixel",
        "canopen": "explore.rigs.canopen",
        "armballs": "explore.rigs.armballs",
        "arm2balls": "explore.rigs.armballs",
    },
    error=RigError,
)


@dataclass(frozen=True)
class RigConfig:
    """How to build a rig.

    Attributes:
        name: a key of ``RIGS``.
        rig_id: identifies a physical rig (its calibration files are found by this id).
        options: the rig's options as given (JSON-like, as ``run.json`` stores them); the rig's
            ``Options`` dataclass checks them and supplies the defaults (``rig_options``).
    """

    name: str = "sim"
    rig_id: str = "twin"
    options: dict[str, Any] = field(default_factory=dict)
    #: its calibration files, once resolved (``resolved``): found on the host that runs it,
    #: never stored in ``run.json``
    calibration: RigCalibration | None = field(default=None, compare=False, repr=False)

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, "rig_id": self.rig_id, "options": dict(self.options)}

    def resolved(self) -> RigConfig:
        """This config with its calibration files found (``calibration``), by its id or the
        files its options name (``arena_calibration``; ``joint_calibration``, ``"none"``: no
        joint file): the one place a rig's files are resolved, once, at the command's entry
        (``open_run``, ``make_rig``), then passed down in the config. A config that has them is
        returned as it is; a bad id is a one-line ``CalibrationError``."""
        if self.calibration is not None:
            return self
        joints = self.options.get("joint_calibration")
        found = RigCalibration.find(
            self.rig_id,
            arena=self.options.get("arena_calibration"),
            joints=None if joints == NO_JOINT_CALIBRATION else joints,
            read_joints=joints != NO_JOINT_CALIBRATION,
        )
        return replace(self, calibration=found)


@dataclass
class Rig:
    """Everything an episode needs.

    A rig with an arm has ``arm``, ``camera``, ``clock`` and ``sensor`` (where the ball is:
    the twin's ground truth or the tracker, ``explore.rigs.ball``), and its episodes are played
    by ``explore.rigs.arm_episodes.EpisodeRunner``. A simulated scene that plays whole
    episodes at once has neither arm, camera, clock nor sensor, and its own ``player``
    instead. ``motor`` turns motor parameters into joint trajectories (the Ergo Jr's DMPs
    unless the rig has its own)."""

    config: RigConfig
    arm: Arm | None = None
    camera: Camera | None = None
    clock: Clock | None = None
    sensor: BallSensor | None = None
    #: motor parameters (n_params,) -> joint trajectory (T, n_joints) rad
    motor: MotorPrimitive = field(default_factory=ergo_jr_dmp)
    #: a rig that plays its own episodes: the run's ``EpisodeConfig`` -> its player; None: the
    #: arm's ``EpisodeRunner``
    player: Callable[[EpisodeConfig], EpisodePlayer] | None = None
    #: seconds between two fsyncs of the run's history (0: after every episode, the default;
    #: ``explore.runs.store.RunStore.sync_interval_s``): a rig whose episode costs well under
    #: a millisecond of computing, which a crash of the machine can only make it redo, need
    #: not wait 2 ms for the disk at each one (a killed process loses nothing either way)
    sync_interval_s: float = 0.0
    #: the rig option ``record_video``: () -> the overhead camera now, a square (side, side, 3)
    #: BGR uint8 frame, taken at every control tick of a movement (``RUN/frames/``); else None
    video_frame: Callable[[], np.ndarray] | None = None

    @cached_property
    def scene(self) -> Scene:
        """The scene the learner and the metric see (``rig_scene``, read once)."""
        return rig_scene(self.config)

    def episodes(self, config: EpisodeConfig | None = None) -> EpisodePlayer:
        """The player of this rig's episodes with timing ``config``: its own, or the arm's."""
        config = config or EpisodeConfig()
        if self.player is not None:
            return self.player(config)
        from explore.rigs.arm_episodes import EpisodeRunner

        return EpisodeRunner(self, config=config)

    def snapshot(self) -> np.ndarray:
        """The scene's state after an episode (the twin's), (k,); empty where nothing can be
        restored (a real arena, a scene reset before every episode)."""
        return self.sensor.snapshot() if self.sensor is not None else NO_STATE

    def restore(self, state: np.ndarray) -> None:
        """Put the scene back in ``state`` (a resumed run's last ``snapshot``; connected), and
        let the arm's step bound start from where its joints are now."""
        if self.sensor is None or not np.size(state):
            return
        self.sensor.restore(state)
        if self.arm is not None:
            self.arm.resync()

    def fault_counts(self) -> dict[str, float] | None:
        """The arm's fault and recovery counters (``Arm.fault_counts``); None without an arm."""
        return self.arm.fault_counts() if self.arm is not None else None

    def connect(self) -> None:
        """The arm first (a port that is missing or busy is the error to name, before any
        camera thread runs), then the camera, then torque on. A rig may lack any of them."""
        if self.arm is not None:
            self.arm.connect()
        try:
            if self.camera is not None:
                self.camera.connect()
            if self.arm is not None:
                self.arm.set_torque(True)
        except BaseException:
            if self.arm is not None:
                self.arm.disconnect(torque_off=True)
            raise
        if self.clock is not None:
            self.clock.restart()

    def disconnect(self, during: BaseException | None = None) -> None:
        """Torque off and close the arm, then the camera; ``during``: the exception that ends
        the run, if any (``robot.arm.Arm.disconnect`` adds a failed torque-off to it)."""
        try:
            if self.arm is not None:
                self.arm.disconnect(torque_off=True, during=during)
        finally:
            if self.camera is not None:
                self.camera.disconnect()

    def __enter__(self) -> Rig:
        self.connect()
        return self

    def __exit__(self, exc_type: object, exc: BaseException | None, tb: object) -> None:
        self.disconnect(during=exc)


def rig_options(config: RigConfig) -> Any:
    """The typed ``Options`` of the rig ``config`` names, from ``config.options``; a
    ``RigError`` (one line, the known options listed) for an unknown rig, option or value."""
    module = RIGS.load(config.name)
    try:
        return parse_options(module.Options, config.options, f"rig {config.name!r}")
    except OptionsError as exc:
        raise RigError(str(exc)) from None


def is_physical(name: str) -> bool:
    """Whether the rig ``name`` drives a real arm (``RigError`` for an unknown rig)."""
    return bool(RIGS.load(name).PHYSICAL)


def make_rig(config: RigConfig) -> Rig:
    """Build (not connect) the rig named in ``config``, its calibration files resolved
    (``RigConfig.resolved``; a bad id is a ``RigError``)."""
    module = RIGS.load(config.name)
    options = rig_options(config)
    try:
        config = config.resolved()
    except CalibrationError as exc:
        raise RigError(f"rig {config.name!r}: {exc}") from None
    return module.make_rig(config, options)


def rig_scene(config: RigConfig) -> Scene:
    """The scene of the rig ``config`` names (its module's ``scene``), without building the
    rig; a ``RigError`` for an unknown rig or bad options."""
    return RIGS.load(config.name).scene(config, rig_options(config))
