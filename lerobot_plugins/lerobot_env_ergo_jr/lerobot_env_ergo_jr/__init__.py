"""The Poppy Ergo Jr's twin as a LeRobot environment (docs/lerobot.md): importing this package
registers the environment type ``ergo_jr`` (``--env.type=ergo_jr``) and its Gymnasium id,
which LeRobot's scripts find by this distribution's name (``register_third_party_plugins``)."""

import gymnasium as gym

from lerobot_env_ergo_jr.config_ergo_jr_env import GYM_ID, ErgoJrEnvConfig

gym.register(GYM_ID, entry_point="lerobot_env_ergo_jr.env:ErgoJrTwinEnv")

__all__ = ["GYM_ID", "ErgoJrEnvConfig"]
