"""One trial of a campaign, the worker side: every (strategy, seed) of an experiment is a
trial that creates or reopens one run folder, runs the usual ``Explorer`` until the campaign's
episode count and returns a ``TrialResult``. It runs in a local worker process or a Ray task
(explore/campaigns/backends.py).

Physical rigs: a trial on a rig other than the twin needs that rig, named by its id; on Ray
it asks for the custom resource ``rig:<rig_id>`` (see ``trial_resources``), which only the
host with that arm advertises, with capacity 1 so that one trial at a time uses an arm. On
the worker, the rig's arena calibration is found by rig id (calibration/store.py).

Files a trial adds to its run folder: ``trial.json`` (host, pid, start and end times, unix
seconds). Like every writer, a trial holds the run's ``writer.lock`` while it runs
(``explore/runs/lock.py``), so two processes never append to one history.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import os
import socket
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from explore.rigs import rig as rigs
from explore.rigs.rig import RigConfig
from explore.runs.layout import TRIAL_FILE
from plumbing.files import atomic_write

# explore.runs.config loads cv2 (vision.observation): imported where a trial is made, as before
if TYPE_CHECKING:
    from explore.runs.config import RunConfig

log = logging.getLogger(__name__)

CAMPAIGN_FILE = "campaign.json"

RIG_RESOURCE_PREFIX = "rig:"  # Ray custom resource of a physical rig: "rig:<rig_id>"


class CampaignError(RuntimeError):
    """A campaign could not be planned or one of its trials failed; the message is one line."""


class TrialLockedError(CampaignError):
    """Another process (another ``ergo experiment`` on the same campaign) is writing the
    trial's run: it was not run here. The message is one line naming that process."""


@dataclass(frozen=True)
class Trial:
    """One (strategy, seed) of a campaign: everything a worker needs, picklable (nothing of it
    is written to disk: ``campaign.json`` holds the campaign's id only).

    Attributes:
        run_dir: absolute path of the run folder; on a cluster it must be on a file system that
            every worker mounts at the same path.
        config: the run's ``RunConfig`` when it is new (rig, strategy and its options, seed,
            episodes the run must hold when the trial ends); a resumed run keeps its own and
            takes only the episode count and the rig options (ports change between sessions).
        campaign_id: the id in ``CAMPAIGN/campaign.json``; a worker that reads another id (or
            none) is not looking at the driver's folder. None for a run outside a campaign.
        resources: Ray custom resources the trial needs (``trial_resources(rig)``).
    """

    run_dir: str
    config: RunConfig
    campaign_id: str | None = None
    resources: dict[str, float] = field(default_factory=dict)

    @classmethod
    def of(
        cls,
        run_dir: str,
        strategy: str,
        seed: int,
        episodes: int,
        options: dict[str, Any] | None = None,
        rig: dict[str, Any] | None = None,
        campaign_id: str | None = None,
        resources: dict[str, float] | None = None,
        warm_start: str | None = None,
    ) -> Trial:
        """The trial of ``strategy`` with ``options`` and ``seed`` on ``rig`` (a ``RigConfig``
        as a dict; the default rig when None) until ``episodes``, warmed by the prior run
        ``warm_start`` (``explore/runs/prior.py``) when given."""
        from explore.runs.config import RunConfig, StrategyConfig

        r = rig or {}
        default = RigConfig()
        rig_config = RigConfig(
            r.get("name", default.name), r.get("rig_id", default.rig_id), dict(r.get("options", {}))
        )
        config = RunConfig(
            rig=rig_config, strategy=StrategyConfig(strategy, dict(options or {})), seed=seed,
            episodes=episodes, warm_start=warm_start,
        )  # fmt: skip
        return cls(str(run_dir), config, campaign_id, dict(resources or {}))

    @property
    def strategy(self) -> str:
        return self.config.strategy.name

    @property
    def seed(self) -> int:
        return self.config.seed

    @property
    def episodes(self) -> int:
        return self.config.episodes

    @property
    def rig(self) -> dict[str, Any]:
        """The rig as a dict (name, rig_id, options)."""
        return self.config.rig.to_dict()

    @property
    def label(self) -> str:
        return f"{self.strategy} seed {self.seed}"


@dataclass(frozen=True)
class TrialResult:
    """What a finished trial reports.

    Attributes:
        strategy, seed: the trial's.
        episodes: episodes in the run folder at the end.
        cells: distinct ball cells reached after the last episode.
        resumed_from: episodes already in the run folder when the trial started (0 = new run).
        host, pid: where it ran.
        started, finished: wall-clock times, unix seconds.
    """

    strategy: str
    seed: int
    episodes: int
    cells: int
    resumed_from: int
    host: str
    pid: int
    started: float
    finished: float

    @property
    def wall_s(self) -> float:
        """Seconds the trial took inside its worker."""
        return self.finished - self.started


# ---- rigs as resources -----------------------------------------------------------------------
def is_physical(rig: dict[str, Any]) -> bool:
    """Whether a trial on this rig needs a real arm (a host that has it): the rig module's
    ``PHYSICAL``; a ``CampaignError`` for an unknown rig."""
    try:
        return rigs.is_physical(rig["name"])
    except rigs.RigError as exc:
        raise CampaignError(str(exc)) from None


def rig_resource(rig_id: str) -> str:
    """The Ray custom resource a host with the arm ``rig_id`` advertises."""
    return f"{RIG_RESOURCE_PREFIX}{rig_id}"


def trial_resources(rig: dict[str, Any]) -> dict[str, float]:
    """Ray custom resources a trial on ``rig`` asks for: ``{"rig:<rig_id>": 1}`` for a
    physical rig (the host advertises capacity 1, so one trial at a time per arm), none for
    the twin."""
    return {rig_resource(rig["rig_id"]): 1.0} if is_physical(rig) else {}


def check_rig_calibration(rig: dict[str, Any]) -> Path | None:
    """On the host that runs a trial on a physical rig: the arena calibration file the rig will
    use (``RigConfig.resolved``: found by rig id, or the ``arena_calibration`` option).

    A campaign on an arm without ball tracking records only unknown (NaN) outcomes for hours,
    so a missing file fails the trial before it starts. None for the twin.
    """
    if not is_physical(rig):
        return None
    from calibration.store import CalibrationError

    try:
        config = RigConfig(rig["name"], rig["rig_id"], dict(rig.get("options", {})))
        path = config.resolved().calibration.arena
    except CalibrationError as exc:
        raise CampaignError(str(exc)) from exc
    if not path.is_file():
        raise CampaignError(
            f"host {socket.gethostname()}: no arena calibration for rig {rig['rig_id']!r} at "
            f"{path}: run 'ergo calibrate arena --rig-id {rig['rig_id']}' on that host"
        )
    return path


# ---- one trial -------------------------------------------------------------------------------
def _check_campaign(trial: Trial) -> None:
    if trial.campaign_id is None:
        return
    marker = Path(trial.run_dir).parents[1] / CAMPAIGN_FILE
    try:
        found = json.loads(marker.read_text()).get("id")
    except (OSError, ValueError):
        found = None
    if found != trial.campaign_id:
        raise CampaignError(
            f"host {socket.gethostname()}: {marker} is missing or from another campaign: the "
            "campaign folder must be on a file system every node mounts at the same path"
        )


def read_json(path: Path) -> dict[str, Any]:
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError):
        return {}
    return data if isinstance(data, dict) else {}


def run_trial(trial: Trial, progress: bool = False) -> TrialResult:
    """Run (or resume) one trial until ``trial.episodes``; runs in the worker (a local process
    or a Ray task). Raises ``CampaignError`` (or the rig's and the strategy's errors) with a
    one-line message."""
    from explore.runs.lock import RunLockedError
    from explore.runs.open_run import open_run
    from explore.runs.progress import ProgressBar
    from explore.runs.store import RunStoreError

    _check_campaign(trial)
    check_rig_calibration(trial.rig)
    path = Path(trial.run_dir)
    started = time.time()
    host, pid = socket.gethostname(), os.getpid()
    try:
        run = open_run(
            path, trial.config, mode="auto", episodes=trial.episodes,
            rig_options=trial.config.rig.options,  # ports change between sessions
        )  # fmt: skip
    except RunLockedError as exc:
        raise TrialLockedError(str(exc)) from exc
    except RunStoreError as exc:
        raise CampaignError(str(exc)) from exc
    with run:  # the history closes before the lock goes
        for note in run.notes():
            log.warning("%s", note)
        info = {"host": host, "pid": pid, "started": started, "resumed_from": run.resumed_from}
        atomic_write(path / TRIAL_FILE, json.dumps(info))
        label = f"{trial.strategy} s{trial.seed}"
        bar = ProgressBar(trial.episodes, run.resumed_from, label, 2.0, False) if progress else None
        try:
            explorer = run.explore(on_episode=bar.update if bar else None)
        finally:
            if bar:
                bar.close()
        rows = explorer.metrics.rows
        cells = int(rows[-1]["ball_cells"]) if rows else 0  # type: ignore[arg-type]
        result = TrialResult(
            trial.strategy, trial.seed, len(run.store), cells, run.resumed_from, host, pid,
            started, time.time(),
        )  # fmt: skip
        atomic_write(path / TRIAL_FILE, json.dumps(dataclasses.asdict(result)))
        return result


def run_one(
    run_dir: str, strategy: str, options: dict[str, Any], seed: int, episodes: int, progress: bool
) -> tuple[str, int, int]:
    """Run (or resume) one (strategy, seed) on the twin in ``run_dir``, outside any campaign;
    returns (strategy, seed, final ball cells)."""
    r = run_trial(Trial.of(str(run_dir), strategy, seed, episodes, options), progress)
    return r.strategy, r.seed, r.cells
