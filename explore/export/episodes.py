"""Episodes of run folders as a dataset sees them: per control tick the joints read, the command
sent and (where the run kept them) the camera frame; per episode the motor parameters, the goal,
the context and the outcome in the run's goal space, and what the strategy was doing.

A run is read without being modified (``explore.runs.store.read_history``): refused in one line
while a process writes it (``writer.lock``) or when its history is corrupt. Its goal space is
its strategy's, rebuilt from ``run.json`` and replayed over the history as a resumed run replays
it (``Strategy.describe`` before each ``update``): engineered spaces are functions of the
record, learned ones encode the outcome images with the run's model (a VAE, loaded from the
path its options name; an online one is trained again, minutes). A strategy without a goal
space (RPE) is described in rge-efr's default space, the ball's wrap-safe polar features.

Tick i of an episode (its frame i) is the moment just before the command of tick i: the joints
read then are ``start_positions`` for i = 0 and ``measured[i - 1]`` after (read at the end of
the previous tick, the same moment); the camera frame of tick i was taken then too
(``explore.rigs.video``). Records written before ``start_positions`` existed use the rest
pose's command for tick 0 (the arm lags it by a degree or two).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from explore.learner.strategies import StrategyError, make_strategy
from explore.rigs.rig import rig_scene
from explore.runs.config import RunConfig
from explore.runs.layout import RUN_FILE, frames_path
from explore.runs.lock import describe_holder, holder_of
from explore.runs.record import EpisodeRecord
from explore.runs.store import RunStoreError, read_frames, read_history
from robot.spec import ergo_jr_spec

# The goal space a run without one (RPE) is described in: rge-efr's, default options.
DESCRIBING_STRATEGY = "rge-efr"


class ExportError(RuntimeError):
    """A run cannot be exported, or runs cannot be exported together (one line)."""


@dataclass
class ExportEpisode:
    """One episode of a run, as a dataset episode.

    Attributes:
        run: the run folder. episode: its index in that run.
        state: joints read at the start of each tick, (T, n_joints) rad.
        action: the command sent at each tick (clamped by the arm's safety), (T, n_joints) rad.
        frames: the overhead camera at the start of each tick, (T, S, S, 3) BGR uint8, or None.
        theta: the motor parameters played, (n_params,) in [-1, 1].
        goal: the goal in the whole goal space, (dim,), NaN outside its module or without one.
        context: the scene before the move in the goal space, (context_dim,).
        outcome: what the move reached in the goal space, (dim,), NaN where not seen.
        task: what the strategy was doing: "motor babbling", "goal in module k" (or its
            noise-free "exploit" form).
    """

    run: Path
    episode: int
    state: np.ndarray
    action: np.ndarray
    frames: np.ndarray | None
    theta: np.ndarray
    goal: np.ndarray
    context: np.ndarray
    outcome: np.ndarray
    task: str

    @property
    def length(self) -> int:
        return len(self.action)


@dataclass(frozen=True)
class RunSource:
    """A run to export, checked: its config, records, goal-space name and whether it kept
    camera frames for every episode.

    Attributes:
        path: the run folder. config: its ``RunConfig``. records: its complete episodes.
        torn_bytes: bytes of a torn last record left out (a crash; 0 if none).
    """

    path: Path
    config: RunConfig
    records: list[EpisodeRecord]
    torn_bytes: int


def task_of(record: EpisodeRecord) -> str:
    """The dataset task of an episode: what the strategy was doing."""
    if record.module < 0 or record.kind == "random":
        return "motor babbling"
    if record.kind == "exploit":
        return f"goal in module {record.module}, exploit (no exploration noise)"
    return f"goal in module {record.module}"


def open_source(path: str | Path) -> RunSource:
    """A run folder checked for export: an ``ExportError`` (one line) for a folder that is not
    a run, a run being written, a corrupt history or a run with no episode."""
    path = Path(path)
    holder = holder_of(path)
    if holder is not None:
        raise ExportError(
            f"{path} is being written ({describe_holder(holder)}): export it once that ergo "
            "explore or campaign trial has stopped"
        )
    try:
        history = read_history(path)
        config = RunConfig.of_run(history.meta["config"], where=path / RUN_FILE)
    except RunStoreError as exc:
        raise ExportError(str(exc) if str(path) in str(exc) else f"{path}: {exc}") from None
    if not history.records:
        raise ExportError(f"{path} holds no episode yet: nothing to export")
    return RunSource(path, config, history.records, history.torn_bytes)


def _describer(source: RunSource) -> Any:
    """The strategy whose ``describe`` gives the run's episodes in its goal space."""
    s = source.config.strategy
    n_params = len(source.records[0].theta)
    scene = rig_scene(source.config.rig)
    try:
        strategy = make_strategy(s.name, n_params=n_params, scene=scene, **s.options)
    except (StrategyError, OSError, ValueError) as exc:
        raise ExportError(f"{source.path}: its goal space cannot be rebuilt: {exc}") from None
    if not hasattr(strategy, "space"):  # no goal space at all (RPE)
        strategy = make_strategy(DESCRIBING_STRATEGY, n_params=n_params, scene=scene)
    return strategy


def _state(record: EpisodeRecord) -> np.ndarray:
    """Joints at the start of each tick, (T, n) rad (see the module doc)."""
    first = record.start_positions
    if first.shape != (record.measured.shape[1],):
        first = ergo_jr_spec().rest  # older records: the rest pose's command
    return np.vstack([first[None], record.measured[:-1]])


def iter_episodes(
    source: RunSource, video: bool, left_out: list[str] | None = None
) -> Iterator[ExportEpisode]:
    """The run's episodes in order (``video``: with their frames). With ``left_out``, an
    episode whose frames are missing or unreadable is left out and named there (one line);
    without, it fails the export."""
    strategy = _describer(source)
    descriptions = []
    for rec in source.records:  # the goal space as the run saw it, episode by episode
        try:
            descriptions.append(strategy.describe(rec))
            strategy.update(rec)
        except StrategyError as exc:
            raise ExportError(f"{source.path}: {exc}") from None
    dims = next(((d.outcome.size, d.context.size) for d in descriptions if d is not None), None)
    if dims is None:
        raise ExportError(f"{source.path}: its strategy never had a goal space over these episodes")
    for rec, d in zip(source.records, descriptions, strict=True):
        try:
            frames = read_frames(source.path, rec.episode) if video else None
            why = "" if frames is not None or not video else "missing"
            if frames is not None and len(frames) != len(rec.targets):
                why = f"{len(frames)} frames for {len(rec.targets)} control ticks"
        except RunStoreError as exc:
            frames, why = None, f"unreadable ({exc})"
        if video and why:
            if left_out is None:
                raise ExportError(
                    f"{source.path}: episode {rec.episode} has no camera frames at the control "
                    f"rate ({why}; run with --rig-option record_video=SIDE, or export with "
                    "--no-video)"
                )
            left_out.append(
                f"{source.path}: episode {rec.episode} left out: its camera frames "
                f"{frames_path(source.path, rec.episode)} are {why} (export with --no-video "
                "to keep every episode without video)"
            )
            continue
        nan_out, nan_ctx = np.full(dims[0], np.nan), np.full(dims[1], np.nan)
        yield ExportEpisode(
            run=source.path,
            episode=rec.episode,
            state=_state(rec),
            action=np.asarray(rec.targets, dtype=float),
            frames=frames,
            theta=np.asarray(rec.theta, dtype=float),
            goal=nan_out if d is None else d.goal,
            context=nan_ctx if d is None else d.context,
            outcome=nan_out if d is None else d.outcome,
            task=task_of(rec),
        )


def has_frames(source: RunSource) -> bool:
    """Whether the run kept camera frames (``record_video``): a file for any of its episodes
    (those missing one are left out of a video export, and named)."""
    return any(frames_path(source.path, rec.episode).is_file() for rec in source.records)
