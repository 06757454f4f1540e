"""The ``sim`` rig: the MuJoCo twin in-process (SimArm + SimCamera + TwinClock)."""

from __future__ import annotations

from explore.clock import TwinClock
from explore.rig import Rig, RigConfig
from sim.arm import SimArm
from sim.camera import SimCamera
from sim.twin import Twin


def make_sim_rig(config: RigConfig) -> Rig:
    """Options: ``render_size`` [h, w] of the overhead frame (default 240 x 240)."""
    size = tuple(config.options.get("render_size", (240, 240)))
    twin = Twin(render_size=size)  # type: ignore[arg-type]
    return Rig(
        arm=SimArm(twin), camera=SimCamera(twin), clock=TwinClock(twin), config=config, twin=twin
    )
