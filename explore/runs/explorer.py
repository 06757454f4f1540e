"""The exploration loop: propose, play, observe, store, learn; resumable from the run folder."""

from __future__ import annotations

import contextlib
import json
import logging
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from explore.learner.strategies.base import Strategy
from explore.rigs.episodes import EpisodeConfig, EpisodePlayer
from explore.rigs.rig import Rig
from explore.runs.fingerprint import FINGERPRINT_KEY, Fingerprint
from explore.runs.layout import FAULTS_FILE
from explore.runs.metrics import METRICS_FILE, MetricsLog
from explore.runs.prior import WarmStart
from explore.runs.record import EpisodeRecord
from explore.runs.store import RunStore, RunStoreError
from plumbing.files import atomic_write
from robot.signals import torque_off_on_signals

log = logging.getLogger(__name__)


def add_fault_counts(run_path: Path, counts: dict[str, float]) -> dict[str, float]:
    """Add one session's ``Arm.fault_counts()`` to ``RUN/faults.json`` (created if missing;
    an unreadable file is kept aside as ``faults.json.bad``). Returns the totals."""
    path = Path(run_path) / FAULTS_FILE
    totals: dict[str, float] = {}
    if path.exists():
        try:
            loaded = json.loads(path.read_text())
            totals = {str(k): float(v) for k, v in loaded["totals"].items()}
            sessions = int(loaded["sessions"])
        except (ValueError, KeyError, TypeError, AttributeError):
            path.replace(path.with_name(FAULTS_FILE + ".bad"))
            totals, sessions = {}, 0
    else:
        sessions = 0
    for k, v in counts.items():
        totals[k] = round(totals.get(k, 0.0) + float(v), 3)
    # a full disk: no half-written file left behind (plumbing.files)
    atomic_write(path, json.dumps({"sessions": sessions + 1, "totals": totals}, indent=1))
    return totals


# The scene's own random stream of an episode (the rig sensor's ``prepare``: the distractor's
# walk), apart from the strategy's: numpy.random.default_rng([seed, episode, SCENE_STREAM]).
SCENE_STREAM = 1


def episode_rng(seed: int, episode: int) -> np.random.Generator:
    """The random stream of one episode: a function of (seed, episode) only, so a resumed run
    draws exactly what the uninterrupted run would have."""
    return np.random.default_rng([seed, episode])


@dataclass
class Progress:
    """What a progress display shows after each episode."""

    episode: int
    total: int
    ball_cells: int
    ee_cells: int
    phase: str
    episodes_per_s: float


class Explorer:
    """Runs a strategy on a rig and records everything into a run store.

    Args:
        rig: a rig, not yet connected (``run`` connects it and turns torque off at the end).
        strategy: the exploration strategy.
        store: the run folder (new or reopened).
        seed: the run's seed.
        episode_config: episode timing.
        on_episode: called with a ``Progress`` after every stored episode.
        on_record: called with each new ``EpisodeRecord`` (recorders, viewers).
        warm: the prior attached to ``strategy`` (``explore/runs/prior.py``), shown each
            record just before the strategy learns it; None: none.
    """

    def __init__(
        self,
        rig: Rig,
        strategy: Strategy,
        store: RunStore,
        seed: int,
        episode_config: EpisodeConfig | None = None,
        on_episode: Callable[[Progress], None] | None = None,
        on_record: Callable[[EpisodeRecord], None] | None = None,
        warm: WarmStart | None = None,
    ) -> None:
        self.rig = rig
        self.warm = warm
        self.strategy = strategy
        self.store = store
        self.seed = seed
        self.runner: EpisodePlayer = rig.episodes(episode_config)
        self.metrics = MetricsLog(store.path / METRICS_FILE, rig.scene)
        self.fingerprint = Fingerprint()  # of the episodes so far (explore/runs/fingerprint.py)
        self.on_episode = on_episode
        self.on_record = on_record
        self.unsaved: list[str] = []  # derived files this session could not write, and why

    def _replay(self) -> None:
        """Rebuild strategy and metrics from the stored history (after a resume)."""
        for rec in self.store:
            if self.warm is not None:
                self.warm.before_update(rec, replay=True)
            self.strategy.update(rec)
            self.fingerprint.add(rec, self.metrics.update(rec))
        try:
            self.metrics.rewrite()
            if self.warm is not None:
                self.warm.rewrite()
        except OSError as exc:
            where = exc.filename or self.metrics.path
            raise RunStoreError(f"cannot write {where}: {exc.strerror or exc}") from exc

    def run(self, n_episodes: int) -> None:
        """Explore until the store holds ``n_episodes`` episodes."""
        self._replay()
        done = len(self.store)
        if done >= n_episodes:
            log.info("run already has %d episodes (asked for %d)", done, n_episodes)
            self._save_fingerprint()
            return
        try:
            self._explore(done, n_episodes)
        except BaseException:
            self._save_fault_counts(failing=True)
            raise
        self._save_fault_counts(failing=False)
        self._save_fingerprint()

    def _save_fingerprint(self) -> None:
        """``run.json``'s fingerprint of the episodes stored (``ergo runs fingerprint``
        recomputes it from the history at any time); a failure to write it is logged."""
        record = self.fingerprint.record()
        if self.store.meta.get(FINGERPRINT_KEY) == record:
            return
        try:
            self.store.replace_meta({**self.store.meta, FINGERPRINT_KEY: record})
        except (OSError, RunStoreError) as exc:
            self.unsaved.append(f"run.json's fingerprint ({exc})")
            log.warning("could not save the fingerprint to %s: %s", self.store.path, exc)

    def _save_fault_counts(self, failing: bool) -> None:
        """``RUN/faults.json`` += this session's counters; never masks the run's own error.
        A failure is logged, or only noted in ``unsaved`` while the run is failing anyway
        (a full disk: the caller reports it with the run's own error). A rig without an arm
        has no counters (and no file)."""
        try:
            counts = self.rig.fault_counts()
            if counts is None:
                return
            add_fault_counts(self.store.path, counts)
        except Exception as exc:  # counters are a report: losing them must not hide a fault
            self.unsaved.append(f"{FAULTS_FILE} ({exc})")
            if not failing:
                log.warning("could not save the fault counters to %s: %s", self.store.path, exc)

    def _explore(self, done: int, n_episodes: int) -> None:
        arm = self.rig.arm
        guard = torque_off_on_signals(arm) if arm is not None else contextlib.nullcontext()
        with self.rig, guard:
            if done:
                self.rig.restore(self.store.records[-1].sim_state)
            start = time.perf_counter()
            for k in range(done, n_episodes):
                row = self.step(k)
                if self.on_episode is not None:
                    rate = (k - done + 1) / max(time.perf_counter() - start, 1e-9)
                    self.on_episode(
                        Progress(
                            k + 1,
                            n_episodes,
                            int(row["ball_cells"]),  # type: ignore[arg-type]
                            int(row["ee_cells"]),
                            self.strategy.phase(),
                            rate,
                        )  # type: ignore[arg-type]
                    )
            # leave the arm at rest before torque goes off
            self.runner.go_rest()

    def step(self, k: int) -> dict[str, object]:
        """Run episode ``k`` (the rig connected), store it durably, then learn from it and
        count it. Returns the episode's metrics row."""
        rec = self.episode(k)
        self.store.append(rec)
        if self.warm is not None:
            self.warm.before_update(rec)
        self.strategy.update(rec)
        row = self.metrics.update(rec)
        self.fingerprint.add(rec, row)
        try:
            self.metrics.append_last()
        except OSError as exc:  # a full disk: the episode is stored, the metrics are derived
            raise RunStoreError(
                f"cannot write {self.metrics.path}: {exc.strerror or exc}; episode {k} is "
                "stored (the metrics are rebuilt on resume)"
            ) from exc
        if self.on_record is not None:
            self.on_record(rec)
        return row

    def episode(self, k: int) -> EpisodeRecord:
        """Run episode ``k``: rest pose, context, proposal, movement, outcome. Its camera frames
        (the rig option ``record_video``) are in the run folder when it returns, before its
        record is appended."""
        t0 = time.perf_counter()
        rng = episode_rng(self.seed, k)
        context = self.runner.context(
            np.random.default_rng([self.seed, k, SCENE_STREAM]),
            render=self.strategy.needs_context_image,
        )
        proposal = self.strategy.propose(context, rng)
        result = self.runner.run(proposal.theta, context)
        if result.frames is not None:
            self.store.write_frames(k, result.frames)
        return EpisodeRecord(
            episode=k,
            theta=np.asarray(proposal.theta, dtype=float),
            goal=np.asarray(proposal.goal, dtype=float),
            module=proposal.module,
            kind=proposal.kind,
            context_ball=context.ball,
            ball=result.outcome.ball,
            context_distractor=context.distractor,
            distractor=result.outcome.distractor,
            ball_moved=result.ball_moved,
            targets=result.targets,
            measured=result.measured,
            end_effector=result.end_effector,
            start_positions=result.start_positions,
            image=result.outcome.image,  # type: ignore[arg-type]
            sim_state=self.rig.snapshot(),
            settle_s=result.settle_s,
            duration_s=time.perf_counter() - t0,
        )
