"""The twin as Gymnasium environments (importing this module registers them):

- ``ergo_explore/ArmBall-v0`` (``ArmBallEnv``): per-tick control at 40 Hz. The action is the
  six joint position targets, sent through the same ``robot.Arm`` safety as every exploration
  (clamped to the joint limits and to 0.15 rad from the previous command); one step is one
  control tick. 200 steps (5 s) an episode. By default the targets are in radians, as the arm
  takes them (what v0 always meant); ``gym.make(..., normalized_actions=True)`` takes them in
  [-1, 1] instead, mapped linearly onto each joint's range (-1 the lower limit, +1 the upper),
  the box RL libraries expect.
- ``ergo_explore/ArmBallDmp-v0`` (``ArmBallDmpEnv``): one step is one exploration episode, the
  IMGEP's own view: the action is the 48 DMP parameters in [-1, 1], played from the rest pose,
  then back to rest and the ball left to settle; the episode ends after that step.

Both observe a ``Dict`` in the GoalEnv style (as gymnasium-robotics' Fetch tasks, so hindsight
relabelling works): ``observation`` the joints read, (6,) rad; ``image`` the 64 x 64 overhead
observation, RGB uint8; ``achieved_goal`` the ball's centre (x, y), m (the twin's ground truth);
``desired_goal`` a ball position drawn on the ring at reset. ``compute_reward(achieved_goal,
desired_goal, info)`` is -1 until the ball is within ``DISTANCE_THRESHOLD`` of the goal, then
0, for single goals or batches; ``compute_terminated`` and ``compute_truncated`` give what
``step`` returns, as gymnasium-robotics' GoalEnvs do. ``render_mode="rgb_array"`` gives the
overhead camera. Seeding
``reset`` makes a rollout deterministic: the twin is, and the ball's start and the goal are
drawn from the environment's generator.

    import gymnasium as gym
    import explore.export.gym_env  # registers the environments
    env = gym.make("ergo_explore/ArmBall-v0", render_mode="rgb_array")
"""

from __future__ import annotations

from typing import Any, ClassVar

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from explore.learner.dmp import N_PARAMS
from explore.learner.experience import Observation
from explore.rigs.arena import R_MAX, R_MIN
from explore.rigs.arm_episodes import EpisodeRunner
from explore.rigs.episodes import EpisodeConfig
from explore.rigs.rig import Rig, RigConfig, make_rig
from robot.spec import CONTROL_RATE_HZ
from sim.models.make_scene import BALL_RADIUS, OUTER_RADIUS
from vision.observation import OBSERVATION_SIZE

# The goal counts as reached when the ball's centre is within one ball radius of it (0.03 m; a
# guess: about two cells of the exploration metric's 30 x 30 grid).
DISTANCE_THRESHOLD = BALL_RADIUS
RENDER_SIDE = 240  # the twin rig's default overhead frame, pixels
MAX_TICKS = 200  # ArmBall-v0 episodes: 5 s at 40 Hz (a guess: a few pushes)


def ring_point(rng: np.random.Generator) -> np.ndarray:
    """A ball position drawn uniformly in area on the ring the ball's centre can reach, (2,) m."""
    r = np.sqrt(rng.uniform(R_MIN**2, R_MAX**2))
    t = rng.uniform(-np.pi, np.pi)
    return np.array([r * np.cos(t), r * np.sin(t)])


class _TwinGoalEnv(gym.Env):
    """What both environments share: the twin rig, the Dict observation, the reward."""

    metadata: ClassVar[dict[str, Any]] = {
        "render_modes": ["rgb_array"],
        "render_fps": CONTROL_RATE_HZ,
    }
    # whether every step ends the episode (the goal does not: reaching it ends nothing)
    TERMINATES_EVERY_STEP: ClassVar[bool] = False

    def __init__(self, render_mode: str | None = None, rig_id: str = "twin") -> None:
        # rig_id: the twin's servos are that rig's fit (``ergo calibrate dynamics``), if any
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode must be None or 'rgb_array', got {render_mode!r}")
        self.render_mode = render_mode
        self.rig: Rig = make_rig(RigConfig("sim", rig_id, {"render_size": [RENDER_SIDE] * 2}))
        self.twin = self.rig.sensor.twin  # type: ignore[union-attr]  # the twin rig's TwinSensor
        self.rig.connect()
        self.spec_arm = self.rig.arm.spec
        n = self.spec_arm.n
        ball = spaces.Box(-OUTER_RADIUS, OUTER_RADIUS, shape=(2,), dtype=np.float32)
        self.observation_space = spaces.Dict(
            {
                "observation": spaces.Box(-np.pi, np.pi, shape=(n,), dtype=np.float32),
                "image": spaces.Box(0, 255, (OBSERVATION_SIZE, OBSERVATION_SIZE, 3), np.uint8),
                "achieved_goal": ball,
                "desired_goal": ball,
            }
        )
        self.goal = np.zeros(2)

    # ---- GoalEnv ---------------------------------------------------------------------------
    def compute_reward(
        self, achieved_goal: np.ndarray, desired_goal: np.ndarray, info: Any = None
    ) -> np.ndarray | float:
        """-1 where the ball is farther than ``DISTANCE_THRESHOLD`` from the goal, else 0; shapes
        (..., 2) m -> (...)."""
        d = np.linalg.norm(np.asarray(achieved_goal) - np.asarray(desired_goal), axis=-1)
        reward = np.where(d > DISTANCE_THRESHOLD, -1.0, 0.0).astype(np.float32)  # 0.0, not -0.0
        return float(reward) if reward.ndim == 0 else reward

    def compute_terminated(
        self, achieved_goal: np.ndarray, desired_goal: np.ndarray, info: Any = None
    ) -> bool | np.ndarray:
        """The ``terminated`` that ``step`` returns for these goals; shapes (..., 2) -> (...)."""
        done = np.full(np.shape(achieved_goal)[:-1], self.TERMINATES_EVERY_STEP)
        return bool(done) if done.ndim == 0 else done

    def compute_truncated(
        self, achieved_goal: np.ndarray, desired_goal: np.ndarray, info: Any = None
    ) -> bool | np.ndarray:
        """Always False, shapes (..., 2) -> (...): the time limit is Gymnasium's ``TimeLimit``
        wrapper's (``max_episode_steps``), as in gymnasium-robotics' Fetch tasks."""
        done = np.zeros(np.shape(achieved_goal)[:-1], dtype=bool)
        return bool(done) if done.ndim == 0 else done

    # ---- gym.Env ---------------------------------------------------------------------------
    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        super().reset(seed=seed)
        twin = self.twin
        twin.reset(ball_xy=tuple(ring_point(self.np_random)))
        self.rig.arm.resync()
        self.goal = ring_point(self.np_random)
        obs = self._observe()
        return obs, self._info(obs)

    def render(self) -> np.ndarray | None:
        if self.render_mode != "rgb_array":
            return None
        return np.ascontiguousarray(self.rig.camera.read().image[..., ::-1])

    def close(self) -> None:
        if self.rig.arm.is_connected:
            self.rig.disconnect()  # torque off
        self.twin.close()

    # ---- helpers ---------------------------------------------------------------------------
    def _observe(self) -> dict[str, np.ndarray]:
        rig = self.rig
        image = rig.sensor.locate(OBSERVATION_SIZE).image  # BGR, rendered at its size
        return {
            "observation": rig.arm.read().positions.astype(np.float32),
            "image": np.ascontiguousarray(image[..., ::-1]),
            "achieved_goal": self.twin.ball_position()[:2].astype(np.float32),
            "desired_goal": self.goal.astype(np.float32),
        }

    def _step_result(
        self, obs: dict[str, np.ndarray], info: dict[str, Any]
    ) -> tuple[dict[str, np.ndarray], float, bool, bool, dict[str, Any]]:
        """``step``'s tuple, from the GoalEnv methods (so they always agree)."""
        achieved, desired = obs["achieved_goal"], obs["desired_goal"]
        return (
            obs,
            float(self.compute_reward(achieved, desired, info)),
            bool(self.compute_terminated(achieved, desired, info)),
            bool(self.compute_truncated(achieved, desired, info)),
            info,
        )

    def _info(self, obs: dict[str, np.ndarray]) -> dict[str, Any]:
        reached = self.compute_reward(obs["achieved_goal"], obs["desired_goal"]) == 0.0
        return {"is_success": bool(reached)}


class ArmBallEnv(_TwinGoalEnv):
    """Per-tick control of the twin: the action is the joint position targets, (6,): rad by
    default, or in [-1, 1] over each joint's range with ``normalized_actions=True``.

    Radians stay the default so that ``ArmBall-v0`` keeps the one meaning it was published
    with (a policy or a dataset of v0 actions still means the same commands); RL libraries
    with Gaussian policies want ``normalized_actions=True``, on which Gymnasium's checker has
    nothing to remark."""

    def __init__(
        self, render_mode: str | None = None, normalized_actions: bool = False, rig_id: str = "twin"
    ) -> None:
        super().__init__(render_mode, rig_id)
        spec = self.spec_arm
        self.normalized_actions = bool(normalized_actions)
        if self.normalized_actions:
            self.action_space = spaces.Box(-1.0, 1.0, shape=(spec.n,), dtype=np.float32)
        else:
            self.action_space = spaces.Box(
                spec.lower.astype(np.float32), spec.upper.astype(np.float32), dtype=np.float32
            )
        self.dt = 1.0 / CONTROL_RATE_HZ

    def joint_targets(self, action: np.ndarray) -> np.ndarray:
        """The joint targets an action asks for, (6,) rad (before the Arm's clamps): the action
        itself, or with ``normalized_actions`` [-1, 1] (clipped) mapped onto [lower, upper]."""
        action = np.asarray(action, dtype=float)
        if not self.normalized_actions:
            return action
        spec = self.spec_arm
        return spec.lower + (np.clip(action, -1.0, 1.0) + 1.0) / 2.0 * (spec.upper - spec.lower)

    def step(
        self, action: np.ndarray
    ) -> tuple[dict[str, np.ndarray], float, bool, bool, dict[str, Any]]:
        sent = self.rig.arm.command(self.joint_targets(action))  # clamped by the Arm
        self.rig.clock.advance(self.dt)
        obs = self._observe()
        info = self._info(obs)
        info["command_sent"] = sent
        return self._step_result(obs, info)


class ArmBallDmpEnv(_TwinGoalEnv):
    """One exploration episode per step: the action is the 48 DMP parameters in [-1, 1]."""

    TERMINATES_EVERY_STEP: ClassVar[bool] = True

    def __init__(self, render_mode: str | None = None) -> None:
        super().__init__(render_mode)
        self.action_space = spaces.Box(-1.0, 1.0, shape=(N_PARAMS,), dtype=np.float32)
        self.runner = EpisodeRunner(self.rig, config=EpisodeConfig())

    def step(
        self, action: np.ndarray
    ) -> tuple[dict[str, np.ndarray], float, bool, bool, dict[str, Any]]:
        theta = np.clip(np.asarray(action, dtype=float), -1.0, 1.0)
        context = Observation(ball=self.twin.ball_position()[:2])
        result = self.runner.run(theta, context)
        obs = self._observe()
        info = self._info(obs)
        info.update(ball_moved=result.ball_moved, settle_s=result.settle_s)
        return self._step_result(obs, info)


# Entry points as "module:Class" strings, so that ``env.spec.to_json()`` can write them.
gym.register(
    "ergo_explore/ArmBall-v0", entry_point=f"{__name__}:ArmBallEnv", max_episode_steps=MAX_TICKS
)
gym.register("ergo_explore/ArmBallDmp-v0", entry_point=f"{__name__}:ArmBallDmpEnv")
