"""A ``Rig`` is an Arm + a Camera + a Clock (+ the twin, when there is one, for ground truth).

Rigs are built by name from a table of name -> "module:factory", imported lazily, so a user
without a CAN adapter library never imports it. A factory takes a ``RigConfig`` and returns
an unconnected ``Rig``.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from explore.clock import Clock
from robot.arm import Arm
from vision.camera import Camera

# name -> "module:function(config) -> Rig"
RIG_FACTORIES: dict[str, str] = {
    "sim": "explore.rig_sim:make_sim_rig",
    "dynamixel": "explore.rig_dynamixel:make_dynamixel_rig",
    "canopen": "explore.rig_canopen:make_canopen_rig",
}


class RigError(RuntimeError):
    """A rig could not be built or connected."""


@dataclass
class RigConfig:
    """How to build a rig. ``options`` holds backend settings (port, can channel, camera URL).

    Attributes:
        name: a key of ``RIG_FACTORIES``.
        rig_id: identifies a physical rig (its calibration files are found by this id).
        options: backend-specific settings, JSON-serialisable.
    """

    name: str = "sim"
    rig_id: str = "twin"
    options: dict[str, Any] = field(default_factory=dict)


@dataclass
class Rig:
    """Everything an episode needs. ``twin`` is the MuJoCo twin for simulated rigs, else None.
    ``ball_locator`` finds the ball in camera frames (the tracker); a rig needs one unless it
    is the twin, whose ground truth is used then."""

    arm: Arm
    camera: Camera
    clock: Clock
    config: RigConfig
    twin: Any = None
    #: frame (H, W, 3) BGR -> ball (x, y) m or NaN; None on the twin = its ground truth
    ball_locator: Callable[[np.ndarray], np.ndarray] | None = None
    #: called with the arm at rest before each episode's context is observed, with the
    #: episode's own random stream for the scene (twin: ball reset, the distractor's walk)
    before_episode: Callable[[np.random.Generator], None] | None = None
    #: side (pixels) -> the square observation (side, side, 3) BGR uint8, rendered directly
    #: at that size; set where nothing needs the full frame (the twin with its ground truth)
    square_view: Callable[[int], np.ndarray] | None = None

    def connect(self) -> None:
        self.camera.connect()
        self.arm.connect()
        self.arm.set_torque(True)
        self.clock.restart()

    def disconnect(self) -> None:
        try:
            self.arm.disconnect(torque_off=True)
        finally:
            self.camera.disconnect()

    def __enter__(self) -> Rig:
        self.connect()
        return self

    def __exit__(self, *exc: object) -> None:
        self.disconnect()


def make_rig(config: RigConfig) -> Rig:
    """Build (not connect) the rig named in ``config``."""
    target = RIG_FACTORIES.get(config.name)
    if target is None:
        raise RigError(f"unknown rig {config.name!r}; choose one of {', '.join(RIG_FACTORIES)}")
    module_name, func_name = target.split(":")
    try:
        module = importlib.import_module(module_name)
    except ImportError as exc:
        raise RigError(f"rig {config.name!r} needs a module that failed to import: {exc}") from exc
    factory = getattr(module, func_name, None)
    if factory is None:
        raise RigError(f"rig {config.name!r} is not available in this version ({target} missing)")
    return factory(config)
