"""A new run's config checked from the command line names the flag that set a bad field
(``explore.runs.config.flag_of``); a run.json keeps naming its fields."""

from __future__ import annotations

import pytest

from explore.rigs.rig import RigConfig
from explore.runs.config import RunConfig, RunConfigError, StrategyConfig, flag_of


@pytest.mark.parametrize(
    "path, flag",
    [
        ("config.strategy.name", "--strategy"),
        ("config.rig.name", "--rig"),
        ("config.rig.rig_id", "--rig-id"),
        ("config.seed", "--seed"),
        ("config.episodes", "--episodes"),
        ("config.warm_start", "--warm-start"),
        ("config.rig.options.render_size", "--rig-option render_size"),
        ("config.rig.options.port", "--port"),
        ("config.rig.options.camera", "--camera"),
        ("config.strategy.options.sigma", "--strategy-option sigma"),
        ("config.episode.rate_hz", "field 'config.episode.rate_hz'"),  # no flag sets it
    ],
)
def test_each_field_is_named_by_its_flag(path, flag):
    assert flag_of(path) == flag


def test_checked_with_flags_names_the_flag_and_without_names_the_field():
    bad = RunConfig(rig=RigConfig("sim"), strategy=StrategyConfig("rge-efr", {"sigma": "lots"}))
    with pytest.raises(RunConfigError) as flags:
        bad.checked(label=flag_of)
    assert str(flags.value) == "--strategy-option sigma must be a number, got 'lots'"
    with pytest.raises(RunConfigError) as fields:
        bad.checked()
    assert str(fields.value).startswith("command line: field 'config.strategy.options.sigma' ")
