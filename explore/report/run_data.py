"""What a report reads of a run folder (``RunData``, ``load_run``) and of a campaign folder
(``find_campaign_runs``). Runs are read without modifying them (safe while an exploration is
still writing).

Two depths: the per-episode metrics (cells reached, ball moved, kind, settle time) come from
``RUN/metrics.csv``, which exploration derived as it went (``records=False``: milliseconds a
run); the positions and goals of each episode need every record of the history decoded
(``records=True``: the history's size, minutes for a campaign of 100k episodes)."""

from __future__ import annotations

import csv
import logging
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from explore.learner.goal_outcomes import goal_outcome_of
from explore.learner.scene import Scene
from explore.report.recorder import recording_paths
from explore.runs.config import RunConfig
from explore.runs.layout import METRICS_FILE, PLANNED_KEY, RUN_FILE
from explore.runs.metrics import MetricsLog, read_metrics
from explore.runs.store import RunStore, iter_history

log = logging.getLogger(__name__)


@dataclass
class RunData:
    """What a report needs from one run (N episodes).

    Attributes:
        episode, ball_cells, ee_cells, settle_s: (N,) per episode (cells reached so far).
        ball_moved: (N,) bool. kind: (N,) str.
        The rest is read from the records, None when only the metrics were read
        (``load_run(records=False)``): module: (N,) int.
        ball, context_ball: (N, 2) m, ball after / before each episode (NaN when not seen).
        ee_final: (N, 2) m, tool tip (x, y) at the end of each movement.
        goals: (N, g) goals, g = 0 when the strategy sets none (NaN-padded: a goal has the
            size of its module, g is the largest).
        reached: (N, g) each episode's outcome in its goal's coordinates (NaN where it has no
            goal or was not seen), or None when the run's goal space cannot be rebuilt
            (``explore.learner.goal_outcomes.goal_outcome_of``: engineered spaces, or a learned
            one whose model is still there).
    """

    path: Path
    meta: dict[str, Any]
    episode: np.ndarray
    ball_cells: np.ndarray
    ee_cells: np.ndarray
    settle_s: np.ndarray
    ball_moved: np.ndarray
    kind: np.ndarray
    module: np.ndarray | None = None
    ball: np.ndarray | None = None
    context_ball: np.ndarray | None = None
    ee_final: np.ndarray | None = None
    goals: np.ndarray | None = None
    reached: np.ndarray | None = None
    recordings: list[Path] = field(default_factory=list)

    @property
    def config(self) -> dict[str, Any]:
        return self.meta["config"]

    @property
    def planned_episodes(self) -> int | str:
        """The episode count planned: the config's, or the last resume's ``--episodes`` that
        changed it (``run.json``'s ``PLANNED_KEY``); ``"?"`` for a config without one."""
        return self.meta.get(PLANNED_KEY, self.config.get("episodes", "?"))

    @property
    def has_records(self) -> bool:
        """Whether the per-episode positions and goals were read (``load_run(records=True)``)."""
        return self.ball is not None

    @property
    def n(self) -> int:
        return len(self.episode)

    @property
    def scene(self) -> Scene:
        """The run's rig's scene (the squares of its figures)."""
        return run_scene(self.config)

    @property
    def strategy(self) -> str:
        return str(self.config.get("strategy", {}).get("name", "?"))

    @property
    def seed(self) -> int:
        return int(self.config.get("seed", 0))

    def final(self) -> dict[str, float]:
        """Final figures: episodes, ball and end-effector cells, fraction that moved the ball."""
        return {
            "episodes": float(self.n),
            "ball_cells": float(self.ball_cells[-1]) if self.n else 0.0,
            "ee_cells": float(self.ee_cells[-1]) if self.n else 0.0,
            "moved_fraction": float(self.ball_moved.mean()) if self.n else 0.0,
        }


def run_scene(config: dict[str, Any]) -> Scene:
    """The scene of the rig a run's config (``run.json``'s ``config``) names; the default
    rig's (``RigConfig()``, a run's default) for a config without a rig."""
    from explore.rigs.rig import RigConfig, rig_scene

    rig = config.get("rig")
    if not isinstance(rig, dict) or "name" not in rig:
        return rig_scene(RigConfig())
    default = RigConfig()
    return rig_scene(
        RigConfig(rig["name"], rig.get("rig_id", default.rig_id), rig.get("options", {}))
    )


def load_run(path: Path, goal_outcomes: bool = True, records: bool = True) -> RunData:
    """Read a run folder (config, history; metrics recomputed from the history).

    ``goal_outcomes``: also map each outcome into the run's goal space (``RunData.reached``,
    for the goals figure). For a latent run that encodes every outcome image with its VAE, the
    slow part of a report; campaign reports do without it.
    ``records=False``: only ``RUN/metrics.csv`` (no positions, goals nor modules), falling
    back to the history when the run has no readable metrics file.
    """
    path = Path(path)
    meta = RunStore.read_meta(path)
    RunConfig.from_dict(meta["config"], where=path / RUN_FILE)  # one line naming a bad field
    if not records:
        derived = _from_metrics(path, meta)
        if derived is not None:
            return derived
    scene = run_scene(meta["config"])
    metrics = MetricsLog(path / METRICS_FILE, scene)  # never written here
    cols: dict[str, list[Any]] = {k: [] for k in ("ball", "context_ball", "ee_final", "goals")}
    module, reached = [], []
    outcome_of = (
        goal_outcome_of(meta["config"].get("strategy", {}), load_models=True, scene=scene)
        if goal_outcomes
        else None
    )
    torn: list[int] = []
    for rec in iter_history(path, torn):
        metrics.update(rec)
        cols["ball"].append(np.asarray(rec.ball, dtype=float))
        cols["context_ball"].append(np.asarray(rec.context_ball, dtype=float))
        cols["ee_final"].append(np.asarray(rec.final_end_effector, dtype=float)[:2])
        cols["goals"].append(np.asarray(rec.goal, dtype=float).ravel())
        module.append(rec.module)
        reached.append(outcome_of(rec) if outcome_of and rec.goal.size else None)
    rows = metrics.rows
    if torn and torn[0]:
        log.warning(
            "%s: left out a torn last record (%d bytes: a crash mid-append, or an append in "
            "progress); the report covers episodes 0..%d", path, torn[0], len(rows) - 1,
        )  # fmt: skip
    g = max((len(x) for x in cols["goals"]), default=0)
    goals = np.full((len(rows), g), np.nan)
    for i, x in enumerate(cols["goals"]):
        goals[i, : len(x)] = x
    reached_arr = None
    if g and outcome_of is not None:
        reached_arr = np.full((len(rows), g), np.nan)
        for i, (x, r) in enumerate(zip(cols["goals"], reached, strict=True)):
            if r is not None and np.size(r) == len(x):
                reached_arr[i, : len(x)] = np.asarray(r, dtype=float).ravel()

    def col(name: str, dtype: Any = float) -> np.ndarray:
        return np.array([r[name] for r in rows], dtype=dtype)

    def pts(name: str) -> np.ndarray:
        return np.asarray(cols[name], dtype=float).reshape(-1, 2)

    return RunData(
        path=path,
        meta=meta,
        episode=col("episode", int),
        ball_cells=col("ball_cells"),
        ee_cells=col("ee_cells"),
        settle_s=col("settle_s"),
        ball_moved=col("ball_moved", int).astype(bool),
        kind=col("kind", str),
        module=np.asarray(module, dtype=int),
        ball=pts("ball"),
        context_ball=pts("context_ball"),
        ee_final=pts("ee_final"),
        goals=goals,
        reached=reached_arr,
        recordings=recording_paths(path),
    )


def _from_metrics(path: Path, meta: dict[str, Any]) -> RunData | None:
    """A run's ``RunData`` from its ``metrics.csv`` alone, or None when it cannot be read."""
    try:
        m = read_metrics(path / METRICS_FILE)
    except (OSError, ValueError, KeyError, TypeError, csv.Error):  # missing, torn, damaged
        return None
    return RunData(
        path=path,
        meta=meta,
        episode=m["episode"].astype(int),
        ball_cells=m["ball_cells"],
        ee_cells=m["ee_cells"],
        settle_s=m["settle_s"],
        ball_moved=m["ball_moved"].astype(bool),
        kind=m["kind"].astype(str),
        recordings=recording_paths(path),
    )


def find_campaign_runs(campaign: Path) -> dict[str, list[Path]]:
    """Runs of a campaign, ``CAMPAIGN/STRATEGY/RUN/run.json``, by strategy folder name."""
    groups: dict[str, list[Path]] = {}
    for meta in sorted(Path(campaign).glob("*/*/run.json")):
        groups.setdefault(meta.parent.parent.name, []).append(meta.parent)
    return groups
