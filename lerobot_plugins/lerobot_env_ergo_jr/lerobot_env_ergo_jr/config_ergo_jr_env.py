"""``--env.type=ergo_jr``: the twin as LeRobot's environment, with the robots' features.

The environment observes ``agent_pos`` (the joints, rad) and ``pixels`` ``{overhead: frame}``
(RGB), which LeRobot maps onto ``observation.state`` and ``observation.images.overhead``;
its action is the joints' goal positions, rad: the names a dataset recorded on the robots (or
exported by ``ergo export lerobot``) gives a policy, so that the policy runs here unchanged.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from lerobot.configs import FeatureType, PolicyFeature
from lerobot.envs.configs import EnvConfig
from lerobot_robot_ergo_jr.config_ergo_jr import TWIN_RIG_ID, check_image_side
from lerobot_robot_ergo_jr.features import (
    ACTION_KEY,
    IMAGE_KEY,
    IMAGE_SIDE,
    IMAGES_PREFIX,
    JOINTS,
    STATE_KEY,
)

from explore.export.gym_env import MAX_TICKS
from robot.spec import CONTROL_RATE_HZ

PACKAGE = "lerobot_env_ergo_jr"
TASK = "ArmBall-v0"  # the twin's per-tick environment (explore/export/gym_env.py)
GYM_ID = f"{PACKAGE}/{TASK}"
# The frame's feature is named as the policy takes it (not "pixels/overhead" as LeRobot's own
# environments do): lerobot-eval --eval.recording=true records features under these names and
# refuses a "/" in one.
IMAGE_FEATURE = IMAGES_PREFIX + IMAGE_KEY


@EnvConfig.register_subclass("ergo_jr")
@dataclass
class ErgoJrEnvConfig(EnvConfig):
    """The twin, one step per control tick.

    Attributes:
        task: ``ArmBall-v0``, the only one: push the ball, a goal drawn on the ring at reset.
        fps: control ticks per second of simulated time (default 40, the project's rate; give
            the dataset's fps, e.g. 30 for ``lerobot-record``'s default).
        episode_length: ticks per episode (default 200: 5 s at 40 Hz).
        image_side: the overhead frame's side, pixels (default 64, as the robots').
        rig_id: the rig whose fitted servos the twin takes, if it has a ``dynamics.json``.
        render_mode: ``rgb_array`` (the overhead camera, for ``lerobot-eval``'s videos).
    """

    task: str | None = TASK
    fps: int = int(CONTROL_RATE_HZ)
    episode_length: int = MAX_TICKS
    image_side: int = IMAGE_SIDE
    rig_id: str = TWIN_RIG_ID
    render_mode: str = "rgb_array"
    features: dict[str, PolicyFeature] = field(
        default_factory=lambda: {
            ACTION_KEY: PolicyFeature(type=FeatureType.ACTION, shape=(len(JOINTS),)),
            "agent_pos": PolicyFeature(type=FeatureType.STATE, shape=(len(JOINTS),)),
        }
    )
    features_map: dict[str, str] = field(
        default_factory=lambda: {
            ACTION_KEY: ACTION_KEY,
            "agent_pos": STATE_KEY,
            IMAGE_FEATURE: IMAGE_FEATURE,
        }
    )

    def __post_init__(self) -> None:
        if self.task != TASK:
            raise ValueError(f"env ergo_jr has one task, {TASK}; got {self.task!r}")
        if self.fps <= 0 or self.episode_length <= 0:
            raise ValueError(
                f"fps and episode_length must be > 0, got {self.fps} and {self.episode_length}"
            )
        check_image_side(self.image_side)
        side = self.image_side
        self.features[IMAGE_FEATURE] = PolicyFeature(type=FeatureType.VISUAL, shape=(side, side, 3))

    @property
    def package_name(self) -> str:
        return PACKAGE

    @property
    def gym_id(self) -> str:
        return GYM_ID

    @property
    def gym_kwargs(self) -> dict:
        return {
            "fps": self.fps,
            "image_side": self.image_side,
            "rig_id": self.rig_id,
            "render_mode": self.render_mode,
            "max_episode_steps": self.episode_length,
        }
