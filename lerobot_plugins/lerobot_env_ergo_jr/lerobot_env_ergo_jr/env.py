"""``ErgoJrTwinEnv``: the twin's ``ergo_explore/ArmBall-v0`` (explore/export/gym_env.py) seen
with LeRobot's names.

Each step sends the action (the joints' goal positions, rad) through the twin's ``robot.Arm``
(clamped to the joint limits and to 0.15 rad from the previous command, as on the robots) and
advances the twin by ``1 / fps`` s. It observes ``agent_pos``, the joints read, (6,) rad, and
``pixels`` ``{"overhead": (side, side, 3) RGB uint8}``, the frame the ``ergo_jr_twin`` robot
observes. Reward and success are ArmBall-v0's: -1 until the ball's centre is within a ball radius
of a goal drawn on the ring at reset, then 0 (``info["is_success"]``).
"""

from __future__ import annotations

from typing import Any, ClassVar

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from lerobot_robot_ergo_jr.features import IMAGE_KEY, IMAGE_SIDE

from explore.export.gym_env import ArmBallEnv
from robot.spec import CONTROL_RATE_HZ
from vision.observation import OBSERVATION_SIZE

# What lerobot-eval asks of an environment for language-conditioned policies (the task's words).
TASK_DESCRIPTION = "push the ball"


class ErgoJrTwinEnv(gym.Env):
    """The twin for ``lerobot-eval`` (see the module docstring).

    Args:
        fps: control ticks per second of simulated time.
        image_side: the overhead frame's side, pixels.
        rig_id: the rig whose fitted servos the twin takes, if it has them.
        render_mode: None or ``rgb_array`` (the overhead camera, full frame).
    """

    metadata: ClassVar[dict[str, Any]] = {
        "render_modes": ["rgb_array"],
        "render_fps": CONTROL_RATE_HZ,
    }

    def __init__(
        self,
        fps: float = CONTROL_RATE_HZ,
        image_side: int = IMAGE_SIDE,
        rig_id: str = "twin",
        render_mode: str | None = None,
    ) -> None:
        self.inner = ArmBallEnv(render_mode=render_mode, rig_id=rig_id)
        self.inner.dt = 1.0 / fps
        self.metadata = {**self.metadata, "render_fps": fps}
        self.render_mode = render_mode
        self.image_side = image_side
        n = self.inner.spec_arm.n
        self.observation_space = spaces.Dict(
            {
                "agent_pos": spaces.Box(-np.pi, np.pi, shape=(n,), dtype=np.float32),
                "pixels": spaces.Dict(
                    {IMAGE_KEY: spaces.Box(0, 255, (image_side, image_side, 3), np.uint8)}
                ),
            }
        )
        self.action_space = self.inner.action_space  # the joint limits, rad
        self.task = self.task_description = TASK_DESCRIPTION

    def _observe(self, inner_obs: dict[str, np.ndarray]) -> dict[str, Any]:
        if self.image_side == OBSERVATION_SIZE:
            image = inner_obs["image"]  # ArmBall-v0's own 64 px frame, RGB
        else:
            frame = self.inner.rig.camera.read_square(self.image_side).image  # type: ignore[union-attr]
            image = np.ascontiguousarray(frame[..., ::-1])
        return {"agent_pos": inner_obs["observation"], "pixels": {IMAGE_KEY: image}}

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, Any], dict[str, Any]]:
        super().reset(seed=seed)
        obs, info = self.inner.reset(seed=seed, options=options)
        return self._observe(obs), info

    def step(self, action: np.ndarray) -> tuple[dict[str, Any], float, bool, bool, dict[str, Any]]:
        obs, reward, terminated, truncated, info = self.inner.step(np.asarray(action, float))
        return self._observe(obs), reward, terminated, truncated, info

    def render(self) -> np.ndarray | None:
        return self.inner.render()

    def close(self) -> None:
        self.inner.close()
