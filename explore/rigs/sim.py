"""The ``sim`` rig: the MuJoCo twin in-process (SimArm + SimCamera + TwinClock)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

from explore.options import BadOption
from explore.rigs.ball import tracker_locator, twin_arena_model
from explore.rigs.clock import TwinClock
from explore.rigs.rig import Rig, RigConfig
from sim import RENDER_QUALITIES
from sim.arm import SimArm
from sim.camera import SimCamera
from sim.twin import Twin

# Rendered frame side, pixels: below 16 the tracker has nothing to see, above 2048 a software
# render takes seconds (guesses, on the safe side).
RENDER_SIDE = (16, 2048)
RENDER_SIZE = f"[height, width], integers in [{RENDER_SIDE[0]}, {RENDER_SIDE[1]}]"
PHYSICAL = False  # nothing physical attached: any host can run it


@dataclass(frozen=True)
class Options:
    """Options of the twin rig.

    Attributes:
        render_size: [height, width] of the overhead frame, pixels (default 240 x 240; with the
            ground truth the outcome image is rendered at its own size and no frame is taken).
        ball: ``truth`` (default: the twin's ground truth) or ``tracker`` (the ball tracker on
            the overhead frames, as on a real rig, with the camera's exact arena model).
        ball_reset: ``none`` (default: the ball stays where the last episode left it, as on the
            real rig) or ``start`` (put back at its start position before every episode, as in
            the paper's simulated ArmBall, where the context never changes).
        render_quality: ``chosen`` (default: the scene's own settings, docs/twin.md) or
            ``legacy`` (MuJoCo's default quality and full frames reduced to the observation,
            the twin's images before 2026-12-01); ``sim.RENDER_QUALITIES``.
    """

    render_size: tuple[int, int] = field(default=(240, 240), metadata={"expected": RENDER_SIZE})
    ball: Literal["truth", "tracker"] = "truth"
    ball_reset: Literal["none", "start"] = "none"
    render_quality: str = "chosen"

    def __post_init__(self) -> None:
        lo, hi = RENDER_SIDE
        if not all(lo <= side <= hi for side in self.render_size):
            raise BadOption("render_size", f"must be {RENDER_SIZE}, got {list(self.render_size)}")
        if self.render_quality not in RENDER_QUALITIES:
            raise BadOption(
                "render_quality",
                f"must be one of {', '.join(RENDER_QUALITIES)}, got {self.render_quality!r}",
            )


def make_rig(config: RigConfig, options: Options) -> Rig:
    """The twin rig (unconnected) with ``options``."""
    twin = Twin(render_size=options.render_size, render_quality=options.render_quality)
    camera = SimCamera(twin)
    locator = tracker_locator(twin_arena_model(camera)) if options.ball == "tracker" else None
    return Rig(
        arm=SimArm(twin), camera=camera, clock=TwinClock(twin), config=config, twin=twin,
        ball_locator=locator,
        before_episode=twin.place_ball if options.ball_reset == "start" else None,
        # with the ground truth, the outcome image is all a frame is for: render it at its size
        square_view=(
            (lambda side: camera.read_square(side).image)
            if locator is None and options.render_quality == "chosen"
            else None  # legacy: reduced from the full frame, as those images were made
        ),
    )  # fmt: skip
