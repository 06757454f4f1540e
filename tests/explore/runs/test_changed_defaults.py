"""A strategy option whose default changed (``runs.config.CHANGED_STRATEGY_DEFAULTS``: goal
exploration's ``stall_window``, 0 before 2026-12-03, 10 since) never changes a made run: a new
run writes today's default into its run.json, and a run.json made before, without the key,
resumes (and is replayed, exported) with the value it was made with."""

from __future__ import annotations

import json

from explore.cli import main
from explore.learner.strategies.goal_exploration import STALL_WINDOW
from explore.runs.config import RunConfig, StrategyConfig
from explore.runs.layout import RUN_FILE
from explore.runs.open_run import open_run
from explore.runs.store import RunStore

RGE = RunConfig(strategy=StrategyConfig("rge-efr", {"bootstrap": 2}), episodes=3)


def test_today_default_differs_from_the_old_one():
    """The test below means something only while the two values differ."""
    assert STALL_WINDOW != 0


def test_a_new_run_writes_the_changed_default_out(tmp_path):
    with open_run(tmp_path / "run", RGE) as opened:
        assert opened.strategy.stall_window == STALL_WINDOW
    held = RunStore.read_meta(tmp_path / "run")["config"]["strategy"]["options"]
    assert held == {"bootstrap": 2, "stall_window": STALL_WINDOW}


def test_a_run_made_before_the_change_resumes_with_the_old_value(tmp_path):
    run = tmp_path / "run"
    with open_run(run, RGE):
        pass
    meta = json.loads((run / RUN_FILE).read_text())
    del meta["config"]["strategy"]["options"]["stall_window"]  # as a run of 2026-12-02 holds
    (run / RUN_FILE).write_text(json.dumps(meta))
    with open_run(run, mode="resume") as opened:
        assert opened.config.strategy.options["stall_window"] == 0
        assert opened.strategy.stall_window == 0
    assert RunConfig.of_run(meta["config"]).strategy.options["stall_window"] == 0
    # the file is left as it was: the old value is read, never written back
    assert (
        "stall_window"
        not in json.loads((run / RUN_FILE).read_text())["config"]["strategy"]["options"]
    )


def test_a_given_value_is_kept_and_a_strategy_without_the_option_is_left_alone():
    given = RunConfig(strategy=StrategyConfig("rge-efr", {"stall_window": 4}))
    assert given.with_defaults_pinned() == given == given.as_made()
    rpe = RunConfig(strategy=StrategyConfig("rpe", {}))
    assert rpe.with_defaults_pinned() == rpe == rpe.as_made()


def test_resuming_with_the_options_given_at_the_start_is_not_refused(tmp_path, capsys):
    """The run.json of a new run holds more than the flags gave (the pinned default): the same
    flags again resume it; a flag that differs is still refused in one line."""
    out = str(tmp_path / "run")
    flags = ["explore", "--strategy", "rge-efr", "--seed", "0", "--out", out, "--no-progress"]
    assert main([*flags, "--episodes", "2", "--strategy-option", "bootstrap=2"]) == 0
    assert main(["explore", "--resume", out, "--episodes", "3", "--no-progress",
                 "--strategy-option", "bootstrap=2"]) == 0  # fmt: skip
    assert main(["explore", "--resume", out, "--episodes", "4", "--no-progress",
                 "--strategy-option", "stall_window=3"]) == 2  # fmt: skip
    assert "a run keeps the strategy options it started with" in capsys.readouterr().err
