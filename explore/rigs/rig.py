"""A ``Rig`` is an Arm + a Camera + a Clock + a motor primitive (+ the twin, when there is one,
for ground truth), or a simulated scene that plays whole episodes itself (``player``: ArmBalls),
and the scene the learner and the metric see (``scene``).

Rigs are built by name from ``RIGS``, a table of name -> module imported lazily
(``robot.registry.LazyTable``), so a user without a CAN adapter library never imports it. Each
rig module defines its typed ``Options`` (a dataclass: unknown keys and wrong types are refused
by ``explore.options.parse_options``), ``make_rig(config, options) -> Rig``, which returns
an unconnected rig, ``PHYSICAL`` (a real arm, or nothing physical attached) and
``scene(config, options) -> explore.learner.scene.Scene`` (cheap: reports ask for it without
building the rig).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from explore.learner.dmp import Dmp, MotorPrimitive
from explore.learner.scene import Scene
from explore.options import OptionsError, parse_options
from explore.rigs.clock import Clock
from explore.rigs.episodes import EpisodePlayer
from robot.arm import Arm
from robot.registry import LazyTable
from vision.camera import Camera


class RigError(RuntimeError):
    """A rig could not be built or connected."""


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

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, "rig_id": self.rig_id, "options": dict(self.options)}


@dataclass
class Rig:
    """Everything an episode needs.

    A rig with an arm has ``arm``, ``camera`` and ``clock``, and its episodes are played by
    ``explore.runs.episode.EpisodeRunner``; ``twin`` is the MuJoCo twin for simulated rigs,
    else None; ``ball_locator`` finds the ball in camera frames (the tracker); a rig needs one
    unless it is the twin, whose ground truth is used then. A simulated scene that plays whole
    episodes at once has neither arm, camera nor clock, and a ``player`` instead. ``motor``
    turns motor parameters into joint trajectories (the Ergo Jr's DMPs unless the rig has its
    own)."""

    config: RigConfig
    arm: Arm | None = None
    camera: Camera | None = None
    clock: Clock | None = None
    twin: Any = None
    #: frame (H, W, 3) BGR -> ball (x, y) m or NaN; None on the twin = its ground truth
    ball_locator: Callable[[np.ndarray], np.ndarray] | None = None
    #: called with the arm at rest before each episode's context is observed, with the
    #: episode's own random stream for the scene (twin: ball reset, the distractor's walk)
    before_episode: Callable[[np.random.Generator], None] | None = None
    #: side (pixels) -> the square observation (side, side, 3) BGR uint8, rendered directly
    #: at that size; set where nothing needs the full frame (the twin with its ground truth)
    square_view: Callable[[int], np.ndarray] | None = None
    #: motor parameters (n_params,) -> joint trajectory (T, n_joints) rad
    motor: MotorPrimitive = field(default_factory=Dmp)
    #: a rig that plays its own episodes: the run's ``EpisodeConfig`` -> its player; None: the
    #: arm's ``EpisodeRunner``
    player: Callable[[Any], EpisodePlayer] | None = None
    #: seconds between two fsyncs of the run's history (0: after every episode, the default;
    #: ``explore.runs.store.RunStore.sync_interval_s``): a rig whose episode costs well under
    #: a millisecond of computing, which a crash of the machine can only make it redo, need
    #: not wait 2 ms for the disk at each one (a killed process loses nothing either way)
    sync_interval_s: float = 0.0
    #: why a physical rig has no ``ball_locator`` (its arena calibration's error), else None
    ball_locator_error: str | None = None
    #: the rig option ``record_video``: () -> the overhead camera now, a square (side, side, 3)
    #: BGR uint8 frame, taken at every control tick of a movement (``RUN/frames/``); else None
    video_frame: Callable[[], np.ndarray] | None = None

    @property
    def scene(self) -> Scene:
        """The scene the learner and the metric see (``rig_scene``)."""
        return rig_scene(self.config)

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

    def disconnect(self) -> None:
        try:
            if self.arm is not None:
                self.arm.disconnect(torque_off=True)
        finally:
            if self.camera is not None:
                self.camera.disconnect()

    def __enter__(self) -> Rig:
        self.connect()
        return self

    def __exit__(self, *exc: object) -> None:
        self.disconnect()


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
    """Build (not connect) the rig named in ``config``."""
    return RIGS.load(config.name).make_rig(config, rig_options(config))


def rig_scene(config: RigConfig) -> Scene:
    """The scene of the rig ``config`` names (its module's ``scene``), without building the
    rig; a ``RigError`` for an unknown rig or bad options."""
    return RIGS.load(config.name).scene(config, rig_options(config))
