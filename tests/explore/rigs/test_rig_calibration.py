"""A rig's calibration files are resolved in one place (``robot.calibration_files.RigCalibration``,
from a ``RigConfig`` by ``RigConfig.resolved``), once at a command's entry, and the value is
passed down: the rig, the run's inputs record and the twin's servos read the files it names,
never their own."""

from __future__ import annotations

from pathlib import Path

import pytest

from explore.rigs.hardware import calibration_files
from explore.rigs.rig import RigConfig
from explore.runs.config import RunConfig, StrategyConfig
from explore.runs.open_run import open_run
from robot.calibration_files import CalibrationError, RigCalibration


def test_a_rig_id_names_its_four_files(tmp_path):
    cal = RigCalibration.find("bench", tmp_path)
    assert (cal.joints, cal.camera, cal.arena, cal.dynamics) == tuple(
        tmp_path / "bench" / f"{kind}.json" for kind in ("joints", "camera", "arena", "dynamics")
    )


def test_named_files_win_and_the_camera_file_is_the_one_beside_the_arena(tmp_path):
    cal = RigCalibration.find(
        "bench", tmp_path, arena=tmp_path / "elsewhere" / "a.json", read_joints=False
    )
    assert cal.arena == tmp_path / "elsewhere" / "a.json"
    assert cal.camera == tmp_path / "elsewhere" / "camera.json"
    assert cal.joints is None
    assert cal.dynamics == tmp_path / "bench" / "dynamics.json"


def test_a_bad_rig_id_is_one_line():
    with pytest.raises(CalibrationError, match=r"rig id '\.\./x' must be") as err:
        RigCalibration.find("../x")
    assert "\n" not in str(err.value)


def test_the_options_name_the_files(tmp_path, _own_calibration_dir):
    config = RigConfig(
        "dynamixel", "bench", {"arena_calibration": str(tmp_path / "a.json"),
                               "joint_calibration": "none"},
    ).resolved()  # fmt: skip
    assert config.calibration.arena == tmp_path / "a.json"
    assert config.calibration.joints is None
    assert config.calibration.dynamics == _own_calibration_dir / "bench" / "dynamics.json"
    assert config.resolved() is config  # resolved once: a resolved config is kept as it is
    assert config.to_dict() == RigConfig("dynamixel", "bench", config.options).to_dict()
    assert config == RigConfig("dynamixel", "bench", config.options)  # not part of its identity


def test_a_resolved_config_is_what_its_readers_read(tmp_path, monkeypatch, _own_calibration_dir):
    """Resolved before the calibration folder moves: the files read are the resolved ones."""
    config = RigConfig("sim", "bench").resolved()
    dynamics = _own_calibration_dir / "bench" / "dynamics.json"
    dynamics.parent.mkdir()
    dynamics.write_text("{}")
    monkeypatch.setenv("ERGO_CALIBRATION_DIR", str(tmp_path / "moved"))
    assert calibration_files(config) == [("dynamics", dynamics)]
    assert calibration_files(RigConfig("sim", "bench")) == []  # resolved now: the moved folder


def test_a_run_resolves_its_rigs_files_once(tmp_path, monkeypatch):
    calls = []
    find = RigCalibration.find.__func__

    def counted(cls, *args, **kwargs):
        calls.append(args)
        return find(cls, *args, **kwargs)

    monkeypatch.setattr(RigCalibration, "find", classmethod(counted))
    config = RunConfig(rig=RigConfig("sim", "bench"), strategy=StrategyConfig("rpe"), episodes=1)
    with open_run(tmp_path / "run", config, mode="new") as run:
        assert run.config.rig.calibration is not None
        assert Path(run.path, "run.json").is_file()
    assert len(calls) == 1


def test_a_campaign_host_checks_the_arena_file_the_rig_will_read(tmp_path, _own_calibration_dir):
    from explore.campaigns.trial import CampaignError, check_rig_calibration

    rig = {"name": "dynamixel", "rig_id": "bench", "options": {}}
    with pytest.raises(CampaignError, match="no arena calibration for rig 'bench'") as err:
        check_rig_calibration(rig)
    assert str(_own_calibration_dir / "bench" / "arena.json") in str(err.value)
    named = tmp_path / "a.json"
    named.write_text("{}")
    rig["options"] = {"arena_calibration": str(named)}
    assert check_rig_calibration(rig) == named
    with pytest.raises(CampaignError, match=r"rig id '\.\./x' must be"):
        check_rig_calibration({"name": "dynamixel", "rig_id": "../x", "options": {}})
    assert check_rig_calibration({"name": "sim", "rig_id": "../x", "options": {}}) is None
