"""LeRobot finds the three plugins by their names, and every robot, teleoperator and the
environment speak the names of ``ergo export lerobot``'s datasets; the configs refuse what would
loosen the arm's safety or name no rig."""

from __future__ import annotations

import importlib.metadata

import pytest
from lerobot.envs.configs import EnvConfig
from lerobot.robots import RobotConfig
from lerobot.teleoperators.config import TeleoperatorConfig
from lerobot.utils.feature_utils import hw_to_dataset_features
from lerobot.utils.import_utils import register_third_party_plugins

from explore.export.lerobot import ROBOT_TYPE, VIDEO_KEY
from explore.export.lerobot import features as export_features
from robot.spec import ERGO_JR_MAX_STEP

PLUGINS = ("lerobot_robot_ergo_jr", "lerobot_teleoperator_ergo_jr", "lerobot_env_ergo_jr")
ROBOTS = ("ergo_jr_dynamixel", "ergo_jr_canopen", "ergo_jr_twin")
TELEOPS = ("ergo_jr_leader", "ergo_jr_scripted")
SIDE = 64


def test_lerobot_finds_each_plugin_by_its_distribution_name():
    names = {d.metadata["Name"] for d in importlib.metadata.distributions()}
    assert set(PLUGINS) <= names  # underscores kept: LeRobot imports the name as a module
    register_third_party_plugins()
    assert set(ROBOTS) <= set(RobotConfig.get_known_choices())
    assert set(TELEOPS) <= set(TeleoperatorConfig.get_known_choices())
    assert "ergo_jr" in EnvConfig.get_known_choices()


def _robot_config(kind: str, **kw):
    import lerobot_robot_ergo_jr as plugin

    configs = {
        "ergo_jr_dynamixel": lambda: plugin.ErgoJrDynamixelConfig(id="a1", port="/dev/null", **kw),
        "ergo_jr_canopen": lambda: plugin.ErgoJrCanopenConfig(id="a1", can="virtual:x", **kw),
        "ergo_jr_twin": lambda: plugin.ErgoJrTwinConfig(**kw),
    }
    return configs[kind]()


@pytest.mark.parametrize("kind", ROBOTS)
def test_every_robot_records_the_exports_features(kind):
    from lerobot.robots.utils import make_robot_from_config

    extra = {} if kind == "ergo_jr_twin" else {"camera": "http://127.0.0.1:1/stream.mjpg"}
    robot = make_robot_from_config(_robot_config(kind, **extra))  # not connected: no bus opened
    assert robot.name == ROBOT_TYPE
    ours = hw_to_dataset_features(robot.observation_features, "observation")
    ours |= hw_to_dataset_features(robot.action_features, "action")
    export = export_features(6, 48, 3, 3, SIDE)
    for key in ("observation.state", "action"):
        assert ours[key]["names"] == export[key]["names"], key
        assert ours[key]["shape"] == tuple(export[key]["shape"]), key
    assert ours[VIDEO_KEY]["shape"] == tuple(export[VIDEO_KEY]["shape"])
    assert set(ours) == {"observation.state", "action", VIDEO_KEY}


@pytest.mark.parametrize("kind", TELEOPS)
def test_every_teleoperator_gives_the_robots_action(kind):
    import lerobot_teleoperator_ergo_jr as plugin
    from lerobot.teleoperators.utils import make_teleoperator_from_config

    config = (
        plugin.ErgoJrLeaderConfig(id="l1", port="/dev/null")
        if kind == "ergo_jr_leader"
        else plugin.ErgoJrScriptedConfig()
    )
    teleop = make_teleoperator_from_config(config)
    robot_action = _robot_config("ergo_jr_twin")
    from lerobot.robots.utils import make_robot_from_config

    assert teleop.action_features == make_robot_from_config(robot_action).action_features


def test_the_environment_gives_a_policy_the_recorded_features():
    from lerobot.envs.utils import env_to_policy_features
    from lerobot_env_ergo_jr import ErgoJrEnvConfig

    env = env_to_policy_features(ErgoJrEnvConfig())
    assert {k: tuple(v.shape) for k, v in env.items()} == {
        "action": (6,),
        "observation.state": (6,),
        VIDEO_KEY: (3, SIDE, SIDE),  # channel first, as a policy takes the dataset's
    }


@pytest.mark.parametrize("kind", ROBOTS)
@pytest.mark.parametrize("step", [ERGO_JR_MAX_STEP * 1.01, 0.0, -0.1, {"m1.pos": 0.1}, None])
def test_max_relative_target_may_tighten_the_step_bound_never_loosen_it(kind, step):
    with pytest.raises(ValueError, match="max_relative_target"):
        _robot_config(kind, max_relative_target=step)
    assert _robot_config(kind, max_relative_target=0.05).max_relative_target == 0.05


@pytest.mark.parametrize("kind", ROBOTS[:2])
def test_an_arm_on_a_bus_needs_its_own_rig_id(kind):
    import lerobot_robot_ergo_jr as plugin

    cls = (
        plugin.ErgoJrDynamixelConfig if kind == "ergo_jr_dynamixel" else plugin.ErgoJrCanopenConfig
    )
    where = {"port": "/dev/null"} if kind == "ergo_jr_dynamixel" else {"can": "virtual:x"}
    with pytest.raises(ValueError, match=r"--robot\.id=ID"):
        cls(**where)
    with pytest.raises(ValueError, match="twin"):
        cls(id="twin", **where)


def test_a_leader_names_one_bus_and_its_rig_id():
    from lerobot_teleoperator_ergo_jr import ErgoJrLeaderConfig

    with pytest.raises(ValueError, match="one bus"):
        ErgoJrLeaderConfig(id="l1")
    with pytest.raises(ValueError, match="one bus"):
        ErgoJrLeaderConfig(id="l1", port="/dev/null", can="virtual:x")
    with pytest.raises(ValueError, match=r"--teleop\.id=ID"):
        ErgoJrLeaderConfig(port="/dev/null")
