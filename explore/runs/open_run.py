"""Opening a run: the one way every writer of a run folder starts (``ergo explore``, campaign
trials, tests, benchmarks).

    with open_run(path, RunConfig(...)) as run:      # a new run, or the one already there
        run.explore()                                # until run.config.episodes

``open_run`` reads the config of a run already in ``path`` (``run.json``, checked) or checks
the one given for a new run, builds the rig and the strategy *before* a new folder is made (a
bad name or option leaves nothing behind), then takes the folder's writer lock (one writer
at a time: a second is refused in one line naming the first's pid) and creates or reopens
the folder (verifying its history and cutting a torn last record). A caller that needs a
special rig or strategy (a fault-injecting arm, an emulator) passes it; everything else
comes from the config.
"""

from __future__ import annotations

import contextlib
import functools
import logging
from collections.abc import Callable
from contextlib import ExitStack
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Literal

from explore.learner.strategies import Strategy, make_strategy
from explore.rigs.rig import Rig, RigError, is_physical, make_rig
from explore.runs.config import RunConfig
from explore.runs.explorer import Explorer, Progress
from explore.runs.inputs import check_inputs, record_inputs
from explore.runs.layout import HISTORY_FILE, NEW_RUN_FILES, PLANNED_KEY, RUN_FILE
from explore.runs.lock import LOCK_FILE, RunLock, RunLockedError, remove_lock_if_free, run_lock
from explore.runs.metrics import recorded_episodes
from explore.runs.prior import WarmStart, attach_prior, check_prior, record_prior
from explore.runs.record import EpisodeRecord
from explore.runs.store import RunStore, RunStoreError, check_own_files, make_run_dir
from robot.calibration_files import CalibrationError

Mode = Literal["new", "resume", "auto"]
log = logging.getLogger(__name__)


@dataclass
class OpenRun:
    """A run folder opened for appending, with the config it runs and what it runs on.

    Attributes:
        config: the run's config (a resumed run's own, with the caller's overrides).
        store: the run folder.
        rig: the rig, built but not connected (``explore`` connects it).
        strategy: the strategy, not yet replayed (``explore`` replays the history first).
        resumed_from: episodes the folder held when it was opened (0 for a new run).
        lock: the folder's writer lock, held until ``close`` (``took_over`` says whether a
            writer that died without releasing it held it before).
        created: whether this open made the folder's run (not a resume).
        missing: episodes the run had stored (``metrics.csv`` says) that its history no
            longer holds (cut short, emptied or deleted): they will be run again.
        inputs_note: what checking the run's input files found worth saying on resume.
        warm: the prior the run is warmed by, attached to ``strategy`` (None: none;
            ``explore/runs/prior.py``).
    """

    config: RunConfig
    store: RunStore
    rig: Rig
    strategy: Strategy
    resumed_from: int
    lock: RunLock | None = None
    created: bool = False
    missing: int = 0
    _held: ExitStack = field(default_factory=ExitStack, repr=False)
    #: what the check of the input files found worth saying on resume (``explore.runs.inputs``)
    inputs_note: list[str] | None = None
    warm: WarmStart | None = None

    @property
    def path(self) -> Path:
        return self.store.path

    def explorer(
        self,
        on_episode: Callable[[Progress], None] | None = None,
        on_record: Callable[[EpisodeRecord], None] | None = None,
    ) -> Explorer:
        """The exploration loop over this run."""
        return Explorer(
            self.rig, self.strategy, self.store, seed=self.config.seed,
            episode_config=self.config.episode, on_episode=on_episode, on_record=on_record,
            warm=self.warm,
        )  # fmt: skip

    def explore(
        self,
        on_episode: Callable[[Progress], None] | None = None,
        on_record: Callable[[EpisodeRecord], None] | None = None,
    ) -> Explorer:
        """Explore until the run holds ``config.episodes`` episodes; returns the explorer (its
        ``metrics`` hold the cells reached)."""
        explorer = self.explorer(on_episode, on_record)
        explorer.run(self.config.episodes)
        return explorer

    def notes(self) -> list[str]:
        """What opening the run found worth saying, one line each: a torn last record cut, a
        history that lost episodes, a dead writer's lock taken over."""
        out = []
        if self.store.truncated_bytes:
            out.append(
                f"{self.path}: moved a torn last record ({self.store.truncated_bytes} bytes: a "
                f"crash or a power cut mid-append) aside to {self.store.moved_aside}; that "
                "episode is run again"
            )
        if self.missing:
            out.append(
                f"{self.path}: the history holds {len(self.store)} episodes but the run had "
                f"stored {len(self.store) + self.missing} (metrics.csv): {self.missing} "
                "episode(s) missing (history.bin cut short, emptied or deleted); they will be "
                "run again"
            )
        takeover = self.lock.describe_takeover() if self.lock is not None else None
        if takeover:
            out.append(takeover)
        out += [note for note in self.inputs_note or []]
        return out

    def close(self) -> None:
        """Close the history, then release the writer lock."""
        self._held.close()

    def __enter__(self) -> OpenRun:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _check_sees_ball(config: RunConfig, rig: Rig, strategy: Strategy) -> None:
    """A rig that cannot locate the ball (a physical rig without an arena calibration) records
    no ball for the whole run: a ``RigError`` for a strategy that needs it (goal exploration),
    else one warning. A rig with nothing physical attached (the twin, ArmBalls) knows where
    its ball is."""
    why = rig.sensor.blind if rig.sensor is not None else None
    if why is None or not is_physical(config.rig.name):
        return
    rig_id = config.rig.rig_id
    calibrate = f"ergo calibrate arena --rig-id {rig_id} --camera ..."
    if strategy.needs_ball:
        raise RigError(
            f"rig {config.rig.name!r} cannot locate the ball that {strategy.name} sets its goals "
            f"on ({why}): run '{calibrate}' first (docs/calibration.md), or give "
            "--rig-option arena_calibration=FILE"
        )
    log.warning(
        "no ball tracking for rig %r (%s): this run will count 0 ball cells; run '%s' first "
        "(docs/calibration.md)", rig_id, why, calibrate,
    )  # fmt: skip


def _with_calibration(config: RunConfig) -> RunConfig:
    """``config`` with its rig's calibration files resolved (``RigConfig.resolved``), once,
    for the rig, its inputs check and record; a bad rig id is a one-line ``RigError``."""
    try:
        return replace(config, rig=config.rig.resolved())
    except CalibrationError as exc:
        raise RigError(f"rig {config.rig.name!r}: {exc}") from None


def open_run(
    path: str | Path,
    config: RunConfig | None = None,
    *,
    mode: Mode = "auto",
    episodes: int | None = None,
    rig_options: dict[str, Any] | None = None,
    check_resumed: Callable[[RunConfig], None] | None = None,
    rig: Rig | None = None,
    strategy: Strategy | None = None,
    allow_changed_inputs: bool = False,
) -> OpenRun:
    """Create the run ``config`` describes in ``path``, or reopen the one there, holding the
    folder's writer lock (``explore/runs/lock.py``) until ``close``.

    Args:
        path: the run folder.
        config: a new run's config (checked here); needed unless the folder holds a run.
        mode: ``"new"`` (the folder must not hold anything), ``"resume"`` (it must hold a run)
            or ``"auto"`` (resume if it holds a run, else create). Which one it is is decided
            under the lock, so two ``auto`` writers never both create.
        episodes, rig_options: on resume, override the run's episode count and add options to
            its rig's (ports change between sessions); a new run takes them from ``config``.
        check_resumed: called with a resumed run's config before anything is built (a CLI
            refusing flags that would change it).
        rig, strategy: use these instead of building them from the config.
        allow_changed_inputs: resume a run whose input files (calibrations, goal-space model:
            ``explore/runs/inputs.py``) changed since it started; else that is refused.

    Raises:
        RunStoreError (a ``RunLockedError`` when another process writes the run, a
        ``RunConfigError`` for a bad config), RigError, StrategyError: one line each; nothing
        is created when the config, the rig or the strategy is bad.
    """
    path = Path(path)
    if mode not in ("new", "resume", "auto"):
        raise ValueError(f"mode must be new, resume or auto, got {mode!r}")
    again = functools.partial(
        open_run, path, config, episodes=episodes, rig_options=rig_options,
        check_resumed=check_resumed, rig=rig, strategy=strategy,
        allow_changed_inputs=allow_changed_inputs,
    )  # fmt: skip
    held = ExitStack()
    made = False  # whether this call made the folder (removed again if the open fails)
    try:
        lock = None
        resume = mode == "resume" or (mode == "auto" and RunStore.is_run(path))
        if resume:
            RunStore.read_meta(path)  # a one-line error for a folder that holds no run
            lock = held.enter_context(run_lock(path))
            check_own_files(path)  # a received folder cannot make us write outside it
            store = RunStore.open(path)  # under the lock: no other writer is appending
            held.callback(store.close)  # unwinds first: the history closes before the lock
            run_config = RunConfig.from_dict(store.config, where=path / RUN_FILE)
            if check_resumed is not None:
                check_resumed(run_config)
            run_config = run_config.as_made()  # options whose default changed since
            if episodes is not None or rig_options:
                run_config = run_config.with_overrides(episodes, rig_options).checked()
            run_config = _with_calibration(run_config)
            # the same calibrations and model as when it started, unless allowed: before
            # anything is built (explore/runs/inputs.py)
            note = check_inputs(store, run_config, allow_changed_inputs)
            # the same prior as when it started, unless allowed (explore/runs/prior.py)
            warmed, prior_note = check_prior(store, run_config, allow_changed_inputs)
            notes = [n for n in (note, prior_note) if n]
            planned = store.meta.get(PLANNED_KEY, store.config.get("episodes"))
            if episodes is not None and run_config.episodes != planned:
                store.replace_meta({**store.meta, PLANNED_KEY: run_config.episodes})
        else:
            if config is None:
                raise RunStoreError(f"{path} holds no run and no config was given for a new one")
            run_config = config.with_overrides(episodes, rig_options).checked()
            run_config = _with_calibration(run_config.with_defaults_pinned())
            store = None
            notes = []
            warmed = run_config.warm_start is not None
        # rig and strategy before a new run folder exists: a bad name leaves nothing
        the_rig = rig if rig is not None else make_rig(run_config.rig)
        the_strategy = strategy if strategy is not None else strategy_for(run_config, the_rig)
        _check_sees_ball(run_config, the_rig, the_strategy)
        # the prior read and attached before a new run folder exists: a bad one leaves nothing
        warm, prior_run = attach_prior(path, run_config, the_rig, the_strategy) if warmed else (
            None, None)  # fmt: skip
        if store is None:
            made = not path.exists()
            make_run_dir(path)
            try:
                lock = held.enter_context(run_lock(path))
            except RunLockedError:
                # another writer holds it (both saw no folder): the folder is its new run,
                # not ours to discard
                made = False
                raise
            if mode == "auto" and RunStore.is_run(path):
                # another writer made the run between our look and our lock: resume it
                held.close()
                return again(mode="resume")
            try:
                store = RunStore.create(path, run_config.to_dict())
            except OSError as exc:  # a full disk, a read-only file system
                raise RunStoreError(
                    f"cannot create the run {path}: {exc.strerror or exc}"
                    + (f" ({exc.filename})" if exc.filename else "")
                ) from exc
            held.callback(store.close)
            record_inputs(store, run_config)
        if prior_run is not None:
            record_prior(store, prior_run)
        store.sync_interval_s = the_rig.sync_interval_s
        missing = 0
        if resume:
            missing = max(0, (recorded_episodes(path) or 0) - len(store))
        return OpenRun(
            run_config, store, the_rig, the_strategy, len(store), lock, not resume, missing, held,
            inputs_note=notes, warm=warm,
        )  # fmt: skip
    except BaseException:
        held.close()
        if made:  # a new run that could not be created (a full or read-only disk)
            with contextlib.suppress(OSError, RunStoreError):
                discard_empty_run(path)
        raise


def discard_empty_run(run: Path) -> None:
    """Remove a run that holds no episode (a new run whose rig failed to connect), so that the
    command that made it can run again: its own files only, then the folder if nothing else
    is left (the lock file aside). Refuses (``RunStoreError``) a run with episodes."""
    run = Path(run)
    history = run / HISTORY_FILE
    if history.exists() and history.stat().st_size:
        raise RunStoreError(f"{run} holds episodes: not removed")
    for name in NEW_RUN_FILES:
        (run / name).unlink(missing_ok=True)
    for tmp in run.glob(f"{RUN_FILE}.tmp*"):  # a create's own temporary file
        tmp.unlink(missing_ok=True)
    left = [p.name for p in run.iterdir()]
    if left == [LOCK_FILE] and remove_lock_if_free(run):
        left = []
    if not left:
        run.rmdir()


def strategy_for(config: RunConfig, rig: Rig | None = None) -> Strategy:
    """The strategy ``config`` describes, for its rig (``rig``, or the one the config names,
    built but not connected): its motor primitive's ``n_params`` and its ``scene``; not yet
    replayed (feed it the run's records with ``update`` to rebuild its state)."""
    rig = rig if rig is not None else make_rig(config.rig)
    s = config.strategy
    return make_strategy(s.name, n_params=rig.motor.n_params, scene=rig.scene, **s.options)
