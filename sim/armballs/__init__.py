"""ArmBalls and Arm-2-Balls: the planar 7-joint arm, the ball it can catch, the distractor it
cannot, observed as 64 x 64 RGB images (docs/armballs.md: every setting and its origin)."""

from sim.armballs.config import ARM_2_BALLS, ARM_BALLS, ArmBallsConfig
from sim.armballs.env import (
    NOT_CAUGHT,
    ArmBallsEnv,
    ArmBallsState,
    EpisodeOutcome,
    EpisodePaths,
    initial_state,
    play_commands,
    step,
)
from sim.armballs.primitives import PrimitiveParameterError, RbfPrimitive
from sim.armballs.render import render_scene

__all__ = [
    "ARM_2_BALLS",
    "ARM_BALLS",
    "NOT_CAUGHT",
    "ArmBallsConfig",
    "ArmBallsEnv",
    "ArmBallsState",
    "EpisodeOutcome",
    "EpisodePaths",
    "PrimitiveParameterError",
    "RbfPrimitive",
    "initial_state",
    "play_commands",
    "render_scene",
    "step",
]
