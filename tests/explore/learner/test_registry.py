"""The strategy registry: one entry per strategy (class, summary, model, options, presets)."""

from __future__ import annotations

import dataclasses

import pytest

from explore.learner.presets import CORL2018
from explore.learner.strategies import STRATEGIES, StrategyError, make_strategy
from explore.learner.strategies.goal_exploration import (
    EngineeredOptions,
    GoalExploration,
    LatentOptions,
    SpatialOptions,
)
from explore.learner.strategies.online import OnlineOptions
from explore.learner.strategies.registry import preset_options
from explore.rigs.arena import TWIN_ARENA

# Run folders name their strategy by these keys (run.json): they must not change.
NAMES = ("rpe", "rge-efr", "mge-efr", "rge-vae", "rge-betavae", "mge-vae", "mge-betavae",
         "rge-online", "rge-sae", "mge-sae")  # fmt: skip


def test_the_names_are_those_run_folders_store():
    assert tuple(STRATEGIES) == NAMES


@pytest.mark.parametrize("name", NAMES)
def test_each_entry_gives_its_options_model_and_product_position(name):
    entry = STRATEGIES[name]
    assert entry.summary
    options = STRATEGIES.options_class(name)
    assert dataclasses.is_dataclass(options)
    suffix = name.partition("-")[2]
    expected = {"efr": EngineeredOptions, "vae": LatentOptions, "betavae": LatentOptions,
                "sae": SpatialOptions, "online": OnlineOptions}.get(suffix)  # fmt: skip
    if expected is not None:
        assert options is expected
    assert entry.goal_exploration == (name != "rpe")
    flag = {"vae": "vae", "betavae": "betavae", "sae": "sae"}.get(suffix)
    assert (entry.model.flag if entry.model else None) == flag
    if entry.model:
        assert entry.model.option in options.__dataclass_fields__
        assert f"--out models/{flag}" in entry.model.recipe
    if "representation" in entry.params:
        assert entry.params == {"modular_default": name.startswith("mge"), "representation": suffix}


def test_one_class_makes_the_product_rge_and_mge():
    rge, mge = (make_strategy(n, scene=TWIN_ARENA) for n in ("rge-efr", "mge-efr"))
    assert type(rge) is type(mge) is GoalExploration
    assert (rge.name, rge.modular, mge.name, mge.modular) == ("rge-efr", False, "mge-efr", True)
    assert [len(m) for m in mge.space.modules] == [3, 2]  # ball, and the hand by default
    assert make_strategy("rge-efr", scene=TWIN_ARENA, modular=True).modular  # the option wins


def test_a_missing_model_names_its_own_recipe():
    for name in ("rge-vae", "mge-betavae", "rge-sae"):
        model = STRATEGIES[name].model
        with pytest.raises(StrategyError, match=f"needs option {model.option}=PATH") as err:
            make_strategy(name, scene=TWIN_ARENA)
        assert model.recipe in str(err.value)


def test_the_corl2018_preset_comes_from_the_entries():
    assert preset_options(CORL2018, "rpe") == {}
    assert preset_options(CORL2018, "rge-efr")["flat"] is True
    assert preset_options(CORL2018, "mge-efr")["flat"] is False
    assert preset_options(CORL2018, "mge-vae")["goals"] == "normal"
    assert preset_options(CORL2018, "rge-sae")["goals"] == "box"
    online = preset_options(CORL2018, "rge-online")
    assert "bootstrap" not in online and online["latents"] == "raw"
    for name in NAMES:  # every option it gives is one the strategy takes
        fields = STRATEGIES.options_class(name).__dataclass_fields__
        assert set(preset_options(CORL2018, name)) <= set(fields), name
    with pytest.raises(StrategyError, match=r"unknown strategy 'rge-efx'.*did you mean"):
        preset_options(CORL2018, "rge-efx")
