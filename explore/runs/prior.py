"""A run warmed by a prior: another run (made on the twin) whose episodes seed its learner
(``ergo explore --warm-start TWIN_RUN``; the rule: ``explore/learner/prior.py``,
docs/warm_start.md).

The prior is kept apart from the run's own data: its episodes are read from its own folder each
time the run is opened, never copied into the run's history, metrics or exports. The run
names it in its config (``RunConfig.warm_start``, the folder's absolute path) and ``run.json``
records what it read under ``PRIOR_KEY``: the path, the SHA-256 of its ``history.bin``, its
episode count, rig and strategy. A resume whose prior changed or is missing is refused in one
line naming the override (``--allow-changed-inputs``, as for the calibration files:
``explore/runs/inputs.py``); with it, ``run.json`` keeps the old record under
``prior_before``, and a missing prior leaves the learner without one for the rest of the run:
``run.json`` records the episode it went missing at (``PRIOR_DETACHED``), and a later resume
never attaches it again, even when its folder is back (the learner that chose the episodes
since had none, so a resume replays every record to a learner without it, and the gap file
gains no row for an episode no prior answered).

The reality gap (``REALITY_GAP_FILE``, a CSV of its own in the run folder): one row per arm
episode whose parameters came from the prior, with the ball before and after that episode in
the prior run and on the arm. Derived, like ``metrics.csv``: rewritten from the history and the
prior on each open, so a kill between an episode and its row loses nothing.
"""

from __future__ import annotations

import csv
import hashlib
import io
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from explore.learner.prior import Prior, PriorAnswer, space_signature, warm_start
from explore.learner.strategies import Strategy, StrategyError, make_strategy
from explore.rigs.rig import Rig, RigConfig, rig_scene
from explore.runs.config import RunConfig
from explore.runs.inputs import ALLOW_FLAG
from explore.runs.layout import HISTORY_FILE, PRIOR_KEY, REALITY_GAP_FILE, RUN_FILE
from explore.runs.lock import is_being_written
from explore.runs.record import EpisodeRecord
from explore.runs.store import RunStore, RunStoreError, read_history
from plumbing.files import atomic_write

PRIOR_BEFORE = "prior_before"  # run.json's key of the prior records replaced by an override
# run.json's key of a prior that went missing at a resume (allowed): {"episode", "path"}; the run
# has no prior from then on
PRIOR_DETACHED = "prior_detached"
CAMPAIGN_MARKER = "campaign.json"  # a campaign folder's (explore/campaigns/trial.py)
GAP_COLUMNS = (
    "episode", "kind", "prior_episode", "prior_context_x", "prior_context_y", "prior_x",
    "prior_y", "arm_context_x", "arm_context_y", "arm_x", "arm_y",
)  # fmt: skip


class PriorError(RunStoreError):
    """A prior that cannot warm this run, or one that changed since the run started (one
    line)."""


def prior_folder(path: str | Path, strategy: str, seed: int) -> Path:
    """The prior run ``path`` names for a run of ``strategy`` with ``seed``: ``path`` itself
    when it is a run folder, ``path/STRATEGY/seed-S`` when it is a campaign (``ergo
    experiment --warm-start CAMPAIGN``: each trial warmed by the twin's run of its strategy and
    seed). Absolute."""
    path = Path(path).expanduser().resolve()
    if RunStore.is_run(path) or not (path / CAMPAIGN_MARKER).is_file():
        return path
    return path / strategy / f"seed-{seed}"


@dataclass
class PriorRun:
    """A prior run as read: ``run.json``, its records, and the SHA-256 of ``history.bin``."""

    path: Path
    meta: dict[str, Any]
    records: list[EpisodeRecord]
    sha256: str

    def record(self) -> dict[str, Any]:
        """What ``run.json`` keeps of it (``PRIOR_KEY``)."""
        config = self.meta["config"]
        return {
            "path": str(self.path), "sha256": self.sha256, "episodes": len(self.records),
            "rig": config["rig"], "strategy": config["strategy"]["name"],
        }  # fmt: skip


def history_sha256(run: Path) -> str | None:
    """The SHA-256 of ``RUN/history.bin`` (hex), or None when it does not exist."""
    try:
        return hashlib.sha256((run / HISTORY_FILE).read_bytes()).hexdigest()
    except FileNotFoundError:
        return None


def read_prior(path: Path, own: Path | None = None) -> PriorRun:
    """Read the prior run in ``path`` (finished: no writer, no torn record). ``own``: the run
    it would warm (refused as its own prior). ``PriorError`` (one line) otherwise."""
    where = f"--warm-start {path}"
    if own is not None and path.resolve() == Path(own).resolve():
        raise PriorError(f"{where}: a run cannot be its own prior")
    if not RunStore.is_run(path):
        raise PriorError(f"{where}: no run there (no {RUN_FILE}): give the twin run's folder")
    if is_being_written(path):
        raise PriorError(f"{where}: the run is being written (its writer holds it): wait for it")
    try:
        history = read_history(path)
    except RunStoreError as exc:
        raise PriorError(f"{where}: {exc}") from exc
    if history.torn_bytes:
        raise PriorError(
            f"{where}: its history ends in a torn record ({history.torn_bytes} bytes): resume "
            f"it (ergo explore --resume {path}) or salvage it first"
        )
    if not history.records:
        raise PriorError(f"{where}: the run holds no episode")
    return PriorRun(path, history.meta, history.records, history_sha256(path) or "")


def check_compatible(prior: PriorRun, config: RunConfig, rig: Rig, strategy: Strategy) -> None:
    """Refuse (``PriorError``, one line) a prior whose run explored another goal space or
    another motor primitive than ``config``'s: the same strategy, the same goal space (form,
    modules, model), the same scene and the same number of motor parameters."""
    where = f"--warm-start {prior.path}"
    try:
        theirs = RunConfig.of_run(prior.meta["config"], prior.path / RUN_FILE)
    except RunStoreError as exc:
        raise PriorError(f"{where}: {exc}") from exc
    name = theirs.strategy.name
    if name != config.strategy.name:
        raise PriorError(
            f"{where}: the prior explored with {name}, this run with {config.strategy.name}: "
            "a prior must come from a run of the same strategy (make one with --strategy "
            f"{config.strategy.name})"
        )
    scene = rig_scene(RigConfig(theirs.rig.name, theirs.rig.rig_id, dict(theirs.rig.options)))
    if scene != rig.scene:
        raise PriorError(
            f"{where}: the prior's rig {theirs.rig.name!r} has another scene ({scene.name}) "
            f"than this run's {config.rig.name!r} ({rig.scene.name})"
        )
    n = int(np.asarray(prior.records[0].theta).size)
    if n != rig.motor.n_params:
        raise PriorError(
            f"{where}: the prior's motor primitive has {n} parameters, this rig's "
            f"{rig.motor.n_params}: not the same arm"
        )
    try:
        made = make_strategy(name, n, scene=rig.scene, **theirs.strategy.options)
    except StrategyError as exc:
        raise PriorError(f"{where}: its strategy cannot be built here: {exc}") from exc
    if space_signature(made) != space_signature(strategy):
        raise PriorError(
            f"{where}: the prior explored another goal space ({space_signature(made)}) than "
            f"this run ({space_signature(strategy)}): give both runs the same representation "
            "options"
        )


class WarmStart:
    """A run's prior attached to its strategy, and the reality-gap file it keeps.

    Args:
        run: the run folder.
        prior: the learner's prior (``explore.learner.prior.Prior``), attached.
        source: the prior run's folder.
    """

    def __init__(self, run: Path, prior: Prior, source: Path) -> None:
        self.path = Path(run) / REALITY_GAP_FILE
        self.prior = prior
        self.source = source
        self.rows: list[dict[str, Any]] = []

    def before_update(self, record: EpisodeRecord, replay: bool = False) -> PriorAnswer | None:
        """Call with each record just before the strategy learns it; a new episode (not a
        replay) whose parameters came from the prior adds its row to the gap file."""
        answer = self.prior.before_update(record)
        if answer is None:
            return None
        row = gap_row(answer, record)
        self.rows.append(row)
        if not replay:
            try:
                new = not self.path.exists()
                with self.path.open("a", newline="") as f:
                    writer = csv.DictWriter(f, GAP_COLUMNS)
                    if new:
                        writer.writeheader()
                    writer.writerow(row)
            except OSError as exc:  # a full disk: the file is derived, rebuilt on resume
                raise RunStoreError(
                    f"cannot write {self.path}: {exc.strerror or exc}; episode "
                    f"{record.episode} is stored (the file is rebuilt on resume)"
                ) from exc
        return answer

    def rewrite(self) -> None:
        """Write the gap file from the rows replayed (after a resume's replay)."""
        text = io.StringIO()
        writer = csv.DictWriter(text, GAP_COLUMNS)
        writer.writeheader()
        writer.writerows(self.rows)
        atomic_write(self.path, text.getvalue())

    def summary(self) -> str:
        """One line: what the prior did in this run so far."""
        p = self.prior
        return (
            f"prior {self.source}: {p.n} episodes; answered {p.answered} of this run's, "
            f"{p.policy.retired_by_reach} entries retired where the arm reached, "
            f"{p.in_play()} episodes still in play"
        )


def gap_row(answer: PriorAnswer, record: EpisodeRecord) -> dict[str, Any]:
    """The gap file's row for an arm episode answered by the prior."""
    values = [
        *answer.prior_context_ball, *answer.prior_ball,
        *np.asarray(record.context_ball, float)[:2], *np.asarray(record.ball, float)[:2],
    ]  # fmt: skip
    return {
        "episode": answer.episode, "kind": answer.kind, "prior_episode": answer.prior_episode,
        **{k: f"{float(v):.6g}" for k, v in zip(GAP_COLUMNS[3:], values, strict=True)},
    }  # fmt: skip


def _write_meta(store: RunStore, meta: dict[str, Any]) -> None:
    atomic_write(store.path / RUN_FILE, json.dumps(meta, indent=2, sort_keys=True))
    store.meta = meta


def check_prior(
    store: RunStore, config: RunConfig, allow_changed: bool = False
) -> tuple[bool, str | None]:
    """On resume, before anything is built: compare ``config.warm_start``'s prior with the
    record ``run.json`` holds.

    Returns:
        whether the run is to be warmed by it (False: no prior, or a missing one allowed), and
        a note for the user (one line) or None.

    Raises:
        PriorError: it changed or went missing and ``allow_changed`` is False (nothing written).
    """
    if config.warm_start is None:
        return False, None
    path = Path(config.warm_start)
    recorded = store.meta.get(PRIOR_KEY)
    now = history_sha256(path) if RunStore.is_run(path) else None
    detached = store.meta.get(PRIOR_DETACHED)
    if detached is None and recorded is None and PRIOR_BEFORE in store.meta:
        detached = {}  # a prior allowed missing before PRIOR_DETACHED was recorded
    if detached is not None:  # missing at an earlier resume: it stays detached
        if now is None:
            return False, None
        at = detached.get("episode", "?") if isinstance(detached, dict) else "?"
        return False, (
            f"{store.path}: its prior {path} is back, but the run went on without it from "
            f"episode {at}: it stays detached for the rest of the run (run.json: "
            f"{PRIOR_DETACHED})"
        )
    if recorded is None:  # a run killed before its record
        return True, None
    if isinstance(recorded, dict) and recorded.get("sha256") == now:
        return True, None
    was = str(recorded.get("sha256"))[:12] if isinstance(recorded, dict) else "?"
    what = "is missing" if now is None else f"changed (sha256 of its history {was} -> {now[:12]})"
    if not allow_changed:
        raise PriorError(
            f"{store.path}: its prior {path} {what} since it started: its learner would not be "
            "the one its episodes were chosen by; restore it, or resume anyway with "
            f"ergo explore --resume {store.path} {ALLOW_FLAG}"
        )
    before = [*list(store.meta.get(PRIOR_BEFORE) or []),
              {"until_episode": len(store), PRIOR_KEY: recorded}]  # fmt: skip
    meta = {k: v for k, v in store.meta.items() if k != PRIOR_KEY}
    if now is None:
        gone = {"episode": len(store), "path": str(path)}
        _write_meta(store, {**meta, PRIOR_BEFORE: before, PRIOR_DETACHED: gone})
        keeps = "run.json keeps the old record"
        return False, (
            f"{store.path}: resumed without its prior {path} ({what}), for the rest of the run; "
            f"{keeps}"
        )
    _write_meta(store, {**meta, PRIOR_BEFORE: before})
    return (
        True,
        f"{store.path}: resumed with its prior {path}, which {what}; run.json keeps the old record",
    )


def attach_prior(
    run: Path, config: RunConfig, rig: Rig, strategy: Strategy
) -> tuple[WarmStart, PriorRun]:
    """Read ``config.warm_start``'s prior, check that it fits, and attach it to ``strategy``
    (not updated yet), for the run in ``run`` (which may not exist yet: nothing is written).
    ``PriorError`` (one line) for a prior that cannot warm this run."""
    prior_run = read_prior(Path(config.warm_start or ""), own=run)
    check_compatible(prior_run, config, rig, strategy)
    name, options = config.strategy.name, config.strategy.options
    try:
        prior = warm_start(
            strategy, lambda: make_strategy(name, rig.motor.n_params, scene=rig.scene, **options),
            prior_run.records,
        )  # fmt: skip
    except StrategyError as exc:
        raise PriorError(str(exc)) from exc
    return WarmStart(run, prior, prior_run.path), prior_run


def record_prior(store: RunStore, prior_run: PriorRun) -> None:
    """Write what the run read of its prior into ``run.json`` (``PRIOR_KEY``)."""
    if store.meta.get(PRIOR_KEY) != prior_run.record():
        _write_meta(store, {**store.meta, PRIOR_KEY: prior_run.record()})
