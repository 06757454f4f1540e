"""The rerun recorder: entity paths and timelines read back from the .rrd with rerun's own
reader, stride, goals, hooks, resume numbering, and ``ergo replay``."""

from __future__ import annotations

import argparse
import dataclasses
import re
from pathlib import Path

import numpy as np
import pytest
import rerun.chunk as rrc

from explore.cli import main
from explore.cli.rerun_flags import add_rerun_arguments, make_recorder
from explore.learner.goal_outcomes import goal_outcome_of, strategy_outcome_of
from explore.report.recorder import (
    EPISODE_ENTITIES,
    GOAL_ENTITIES,
    JOINT_NAMES,
    STATIC_ENTITIES,
    STRIDE_ENTITIES,
    Recorder,
    next_recording_path,
    recording_paths,
    run_recording_id,
)
from explore.rigs.arena import TWIN_ARENA
from explore.runs.config import RunConfig, StrategyConfig
from explore.runs.layout import METRICS_FILE, RECORDING_FILE
from explore.runs.open_run import open_run
from explore.runs.store import iter_history
from plumbing.cli_errors import CliError

N = 8
# one line of ChunkStore.summary(): "{entity}  rows={n}  static={bool}  timelines=[...]  cols=[...]"
SUMMARY_LINE = re.compile(
    r"^(?P<entity>\S+)\s+rows=(?P<rows>\d+)\s+static=(?P<static>\w+)\s+timelines=\[(?P<timelines>[^]]*)\]"
)
STRIDE = 3


def read_rrd(path: Path) -> tuple[dict[str, int], dict[str, set[str]], rrc.RrdReader]:
    """Rows per (non-static) entity path and timelines per entity path, via rerun's reader."""
    reader = rrc.RrdReader(path)
    store = reader.stream().collect()
    rows: dict[str, int] = {}
    timelines: dict[str, set[str]] = {}
    for line in store.summary().splitlines():
        m = SUMMARY_LINE.match(line)
        assert m, line
        entity = m["entity"].lstrip("/")
        tls = {t.strip(" '") for t in m["timelines"].split(",") if t.strip(" '")}
        timelines.setdefault(entity, set()).update(tls)
        if m["static"] == "False":
            rows[entity] = rows.get(entity, 0) + int(m["rows"])
    return rows, timelines, reader


def explore_with_recorder(
    out: Path,
    recorder_path: Path,
    episodes: int = N,
    strategy: dict | None = None,
    live_outcomes: bool = False,
) -> Path:
    """Explore the twin with a recorder saving ``recorder_path``; ``live_outcomes``: the
    recorder reads the running strategy's goal space (else none, or the config's)."""
    strategy = strategy or {"name": "rpe", "options": {}}
    config = RunConfig(strategy=StrategyConfig(**strategy), seed=1, episodes=episodes)
    with open_run(out, config, mode="new") as run:
        recorder = Recorder(
            "save",
            path=recorder_path,
            stride=STRIDE,
            recording_id=run_recording_id(out),
            outcome_of=strategy_outcome_of(run.strategy) if live_outcomes else None,
            scene=TWIN_ARENA,
        )
        try:
            run.explore(on_record=recorder.on_record, on_episode=recorder.on_progress)
        finally:
            recorder.close()
    return out


@pytest.fixture(scope="module")
def recorded_run(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("rec") / "run"
    explore_with_recorder(out, out / RECORDING_FILE)
    return out


def test_recording_has_the_documented_entities_and_timelines(recorded_run):
    rows, timelines, reader = read_rrd(recorded_run / RECORDING_FILE)
    for entity in (
        *EPISODE_ENTITIES,
        *STRIDE_ENTITIES,
        *STATIC_ENTITIES,
        "progress/episodes_per_s",
    ):
        assert entity in timelines, entity
    for entity in EPISODE_ENTITIES:
        assert rows[entity] == N, entity
        assert {"episode", "time"} <= timelines[entity], entity
    n_heavy = len(range(0, N, STRIDE))
    assert rows["camera/outcome"] == n_heavy
    assert rows["arm/end_effector"] == n_heavy
    # joint trajectories: T ticks per logged episode, on both timelines
    t_ticks = next(iter(iter_history(recorded_run))).targets.shape[0]
    for name in JOINT_NAMES:
        assert rows[f"joints/{name}"] == n_heavy * t_ticks
        assert {"episode", "time"} <= timelines[f"joints/{name}"]
    assert not any(e.startswith("goal/") for e in timelines)  # RPE sets no goals
    assert reader.blueprints(), "the default blueprint is stored with the recording"
    assert reader.recordings()[0].application_id == "ergo-explore"


def test_cells_logged_match_the_run_metrics(recorded_run):
    from explore.runs.metrics import read_metrics

    m = read_metrics(recorded_run / METRICS_FILE)
    rec = Recorder("save", path=recorded_run / "check.rrd", scene=TWIN_ARENA)
    rec.prime(iter_history(recorded_run))
    rec.close()
    assert rec.ball_cells.count == int(m["ball_cells"][-1])
    assert rec.ee_cells.count == int(m["ee_cells"][-1])
    assert rec.n_moved == int(m["ball_moved"].sum())


def test_goals_and_hooks(recorded_run, tmp_path):
    base = next(iter(iter_history(recorded_run)))
    path = tmp_path / "g.rrd"
    with Recorder("save", path=path, outcome_of=lambda r: r.goal + 0.1, scene=TWIN_ARENA) as rec:
        for k in range(3):
            rec.on_record(dataclasses.replace(base, episode=k, goal=np.full(10, 0.5 * k)))
            rec.log_frame("vae/reconstruction", np.random.default_rng(k).random((64, 64, 3)))
            rec.log_scalar("interest/module0", 0.1 * k)
            rec.log_scalar("bus/no_status_packets", k)
        rec.log_frame("grey", np.zeros((8, 8), np.uint8))
    rows, timelines, _ = read_rrd(path)
    for entity in GOAL_ENTITIES:
        assert rows[entity] == 3, entity
    assert rows["frames/vae/reconstruction"] == 3
    assert rows["series/interest/module0"] == 3
    assert {"episode", "time"} <= timelines["series/bus/no_status_packets"]
    assert "frames/grey" in rows


GOAL_RUN = {"name": "rge-efr", "options": {"bootstrap": 3, "random_episodes": 0}}
N_GOAL = 7


@pytest.fixture(scope="module")
def goal_run(tmp_path_factory) -> Path:
    """A goal-exploration run on the twin (3 random episodes, then 4 with goals), recorded
    with the running strategy's goal space."""
    out = tmp_path_factory.mktemp("goal") / "run"
    explore_with_recorder(out, out / RECORDING_FILE, N_GOAL, GOAL_RUN, live_outcomes=True)
    return out


def test_goal_exploration_logs_goal_and_reached_in_goal_space(goal_run):
    records = list(iter_history(goal_run))
    with_goal = [r for r in records if r.goal.size]
    assert len(with_goal) == N_GOAL - 3
    seen = [r for r in with_goal if np.all(np.isfinite(r.ball))]
    rows, timelines, _ = read_rrd(goal_run / RECORDING_FILE)
    assert rows["goal/target"] == len(with_goal)
    for entity in ("goal/reached", "goal/miss", "goal/error"):
        assert rows[entity] == len(seen), entity
        assert {"episode", "time"} <= timelines[entity]
    # the reached outcome is the record's ball in the goal's coordinates (wrap-safe polar)
    from explore.learner.goal_spaces import wrap_safe_features

    outcome_of = goal_outcome_of(GOAL_RUN, TWIN_ARENA)  # from the config alone: the same map
    assert outcome_of is not None
    for r in seen:
        reached = outcome_of(r)
        assert reached is not None and reached.shape == r.goal.shape
        np.testing.assert_allclose(reached, wrap_safe_features(r.ball[:2], TWIN_ARENA.ring))
    assert outcome_of(records[0]) is None  # a random episode has no module


def test_goal_outcome_of_needs_a_goal_space():
    assert goal_outcome_of({"name": "rpe", "options": {}}, TWIN_ARENA) is None
    assert goal_outcome_of({"name": "no-such-strategy"}, TWIN_ARENA) is None
    # a learned space is not loaded unless asked (and rge-vae without a model cannot be built)
    assert goal_outcome_of({"name": "rge-vae", "options": {}}, TWIN_ARENA) is None
    assert goal_outcome_of({"name": "rge-vae", "options": {}}, TWIN_ARENA, load_models=True) is None


def test_make_recorder_derives_goal_outcomes_from_the_run_config(goal_run, tmp_path):
    parser = argparse.ArgumentParser()
    add_rerun_arguments(parser)
    rec = make_recorder(parser.parse_args([]), goal_run, records=[])
    assert rec is not None and rec.outcome_of is not None
    rec.close()


def test_make_recorder_numbers_files_on_resume_and_continues_counts(recorded_run, tmp_path):
    parser = argparse.ArgumentParser()
    add_rerun_arguments(parser)
    assert make_recorder(parser.parse_args(["--rerun", "off"]), recorded_run) is None
    with pytest.raises(CliError):
        make_recorder(parser.parse_args(["--rerun-stride", "0"]), recorded_run)
    args = parser.parse_args(["--rerun-stride", "2"])
    assert next_recording_path(recorded_run) == recorded_run / "recording-2.rrd"
    rec = make_recorder(args, recorded_run)
    assert rec is not None and rec.path == recorded_run / "recording-2.rrd"
    assert rec.n_episodes == N and rec.stride == 2  # primed from the stored history
    assert rec.clock_s > 0
    rec.close()
    assert recording_paths(recorded_run)[:2] == [
        recorded_run / RECORDING_FILE,
        recorded_run / "recording-2.rrd",
    ]
    # a resumed session's file shares the run's recording id (the viewer merges them)
    ids = {rrc.RrdReader(p).recordings()[0].recording_id for p in recording_paths(recorded_run)}
    assert len(ids) == 1


def test_replay_prints_the_viewer_command(recorded_run, capsys, monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    assert main(["replay", str(recorded_run), "--print"]) == 0
    line = capsys.readouterr().out.strip().splitlines()[-1]
    assert line.startswith("rerun ") and str((recorded_run / RECORDING_FILE).resolve()) in line


def test_replay_writes_a_recording_when_the_run_has_none(recorded_run, tmp_path, capsys):
    import shutil

    bare = tmp_path / "bare"
    bare.mkdir()
    for name in ("run.json", "history.bin"):
        shutil.copy(recorded_run / name, bare / name)
    assert main(["replay", str(bare), "--print"]) == 0
    rows, _, _ = read_rrd(bare / RECORDING_FILE)
    assert rows["arena/ball"] == N


def test_replay_refuses_a_non_run(tmp_path):
    assert main(["replay", str(tmp_path)]) == 2
