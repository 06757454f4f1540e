"""The ``sim`` rig: the MuJoCo twin in-process (SimArm + SimCamera + TwinClock)."""

from __future__ import annotations

from explore.rigs.ball import tracker_locator, twin_arena_model
from explore.rigs.clock import TwinClock
from explore.rigs.rig import Rig, RigConfig, RigError
from sim import RENDER_QUALITIES
from sim.arm import SimArm
from sim.camera import SimCamera
from sim.twin import Twin


def make_sim_rig(config: RigConfig) -> Rig:
    """Options: ``render_size`` [h, w] of the overhead frame (default 240 x 240; with the ground
    truth the outcome image is rendered at its own size and no frame is taken); ``ball``:
    ``truth`` (default: the twin's ground truth) or ``tracker`` (the ball tracker on the
    overhead frames, as on a real rig, with the camera's exact arena model); ``ball_reset``:
    ``none`` (default: the ball stays where the last episode left it, as on the real rig) or
    ``start`` (put back at its start position before every episode, as in the paper's
    simulated ArmBall, where the context never changes); ``render_quality``: ``chosen``
    (default: the scene's own settings, docs/twin.md) or ``legacy`` (MuJoCo's default quality
    and full frames reduced to the observation, the twin's images before 2026-12-01)."""
    size = tuple(config.options.get("render_size", (240, 240)))
    ball = config.options.get("ball", "truth")
    if ball not in ("truth", "tracker"):
        raise RigError(f"rig option ball={ball!r}: expected 'truth' or 'tracker'")
    reset = config.options.get("ball_reset", "none")
    if reset not in ("none", "start"):
        raise RigError(f"rig option ball_reset={reset!r}: expected 'none' or 'start'")
    quality = config.options.get("render_quality", "chosen")
    if quality not in RENDER_QUALITIES:
        raise RigError(
            f"rig option render_quality={quality!r}: expected one of {', '.join(RENDER_QUALITIES)}"
        )
    twin = Twin(render_size=size, render_quality=quality)  # type: ignore[arg-type]
    camera = SimCamera(twin)
    locator = tracker_locator(twin_arena_model(camera)) if ball == "tracker" else None
    return Rig(
        arm=SimArm(twin), camera=camera, clock=TwinClock(twin), config=config, twin=twin,
        ball_locator=locator, before_episode=twin.place_ball if reset == "start" else None,
        # with the ground truth, the outcome image is all a frame is for: render it at its size
        square_view=(
            (lambda side: camera.read_square(side).image)
            if locator is None and quality == "chosen"
            else None  # legacy: reduced from the full frame, as those images were made
        ),
    )  # fmt: skip
