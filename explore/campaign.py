"""Campaigns: every (strategy, seed) of an experiment is a trial that writes one run folder.

A campaign is a folder ``CAMPAIGN/STRATEGY/seed-S`` of ordinary run folders (explore/store.py)
plus ``CAMPAIGN/campaign.json`` (its id) and ``CAMPAIGN/summary.csv``. A trial creates or
reopens its run folder, runs the usual ``Explorer`` until the campaign's episode count and
returns a ``TrialResult``. Trials run through a backend, from a table of name ->
"module:function" imported lazily (as the rigs are): ``local`` (this machine's processes, no
Ray) and ``ray`` (Ray tasks on a cluster, explore/campaign_ray.py).

Resumable whatever dies: finished trials are skipped, unfinished ones resume from their run
folder (the history is append-only and fsync'ed per episode, so a killed worker loses at most
the episode in flight; on the twin the resumed history equals an uninterrupted one).

Physical rigs: a trial on a rig other than the twin needs that rig, named by its id; on Ray
it asks for the custom resource ``rig:<rig_id>`` (see ``trial_resources``), which only the
host with that arm advertises, with capacity 1 so that one trial at a time uses an arm. On
the worker, the rig's arena calibration is found by rig id (calibration/store.py).

Files a trial adds to its run folder: ``trial.json`` (host, pid, start and end times, unix
seconds) and ``trial.lock`` (an exclusive ``flock`` held while the trial runs, so two
processes never append to one history).
"""

from __future__ import annotations

import csv
import dataclasses
import fcntl
import importlib
import json
import os
import socket
import sys
import time
import uuid
from collections.abc import Callable, Iterator
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

CAMPAIGN_FILE = "campaign.json"
TRIAL_FILE = "trial.json"
LOCK_FILE = "trial.lock"

# backend name -> "module:function(trials, settings) -> list[TrialResult]", imported lazily so
# that the local backend never imports Ray
BACKENDS: dict[str, str] = {
    "local": "explore.campaign:run_local",
    "ray": "explore.campaign_ray:run_ray",
}
# rigs with nothing physical attached: any host can run them (explore/rig.py RIG_FACTORIES)
VIRTUAL_RIGS = frozenset({"sim"})
RIG_RESOURCE_PREFIX = "rig:"  # Ray custom resource of a physical rig: "rig:<rig_id>"
TWIN_RIG: dict[str, Any] = {"name": "sim", "rig_id": "twin", "options": {}}
# Restarts of a trial whose worker or node died (a guess: enough for a node lost once or a
# worker killed by an OOM spike, few enough that a trial that kills its worker every time
# does not hold a rig for long).
DEFAULT_RETRIES = 2

# strategies that need a representation trained beforehand, and the flag that gives it (the
# key of ``run_campaign``'s ``models``, of ``MAKE_VAE`` and the ergo experiment flag)
MODEL_FLAGS = {
    "rge-vae": "vae", "mge-vae": "vae", "rge-betavae": "betavae", "mge-betavae": "betavae",
    "rge-sae": "sae", "mge-sae": "sae",
}  # fmt: skip
# the strategy option that names the model, per flag
MODEL_OPTION = {"vae": "vae", "betavae": "vae", "sae": "sae"}


class CampaignError(RuntimeError):
    """A campaign could not be planned or one of its trials failed; the message is one line."""


@dataclass(frozen=True)
class Trial:
    """One (strategy, seed) of a campaign: everything a worker needs, JSON-like and picklable.

    Attributes:
        run_dir: absolute path of the run folder; on a cluster it must be on a file system that
            every worker mounts at the same path.
        strategy: strategy name (explore/strategies).
        seed: the run's seed.
        episodes: episodes the run must hold when the trial ends.
        options: the strategy's options.
        rig: a ``RigConfig`` as a dict (name, rig_id, options).
        campaign_id: the id in ``CAMPAIGN/campaign.json``; a worker that reads another id (or
            none) is not looking at the driver's folder. None for a run outside a campaign.
        resources: Ray custom resources the trial needs (``trial_resources(rig)``).
    """

    run_dir: str
    strategy: str
    seed: int
    episodes: int
    options: dict[str, Any] = field(default_factory=dict)
    rig: dict[str, Any] = field(default_factory=lambda: dict(TWIN_RIG))
    campaign_id: str | None = None
    resources: dict[str, float] = field(default_factory=dict)

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


@dataclass(frozen=True)
class BackendSettings:
    """How a backend runs trials.

    Attributes:
        jobs: local: processes at once; ray: CPUs of a Ray instance started for this campaign
            (ignored when joining a cluster, whose CPUs decide). None = the backend's default.
        progress: progress bars (local) or one line per finished trial (both), on stderr.
        ray_address: ray: the cluster to join (``HOST:PORT`` or ``auto``); None = start a
            local Ray instance on 127.0.0.1 for the campaign.
        retries: ray: times a trial is restarted after its worker or node died (it resumes
            from its run folder); errors raised by the trial itself are never retried.
    """

    jobs: int | None = None
    progress: bool = False
    ray_address: str | None = None
    retries: int = DEFAULT_RETRIES


# ---- rigs as resources -----------------------------------------------------------------------
def is_physical(rig: dict[str, Any]) -> bool:
    """Whether a trial on this rig needs a real arm (a host that has it)."""
    return rig["name"] not in VIRTUAL_RIGS


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
    use (found by rig id, calibration/store.py, or the ``arena_calibration`` option).

    A campaign on an arm without ball tracking records only unknown (NaN) outcomes for hours,
    so a missing file fails the trial before it starts. None for the twin.
    """
    if not is_physical(rig):
        return None
    from calibration.store import CalibrationError, calibration_path

    named = rig.get("options", {}).get("arena_calibration")
    try:
        path = Path(named) if named else calibration_path("arena", rig["rig_id"])
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


@contextmanager
def _trial_lock(run_dir: Path) -> Iterator[None]:
    """Hold ``RUN/trial.lock`` exclusively, or fail at once naming who holds it."""
    fd = os.open(run_dir / LOCK_FILE, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = _read_json(run_dir / TRIAL_FILE)
            raise CampaignError(
                f"{run_dir} is being run by another process (host {holder.get('host')}, "
                f"pid {holder.get('pid')})"
            ) from None
        yield
    finally:
        os.close(fd)  # releases the lock


def _read_json(path: Path) -> dict[str, Any]:
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError):
        return {}
    return data if isinstance(data, dict) else {}


def _new_config(trial: Trial) -> dict[str, Any]:
    from explore.episode import EpisodeConfig

    return {
        "rig": {"name": trial.rig["name"], "rig_id": trial.rig["rig_id"],
                "options": dict(trial.rig.get("options", {}))},
        "strategy": {"name": trial.strategy, "options": trial.options},
        "seed": trial.seed,
        "episodes": trial.episodes,
        "episode": dataclasses.asdict(EpisodeConfig()),
    }  # fmt: skip


def run_trial(trial: Trial, progress: bool = False) -> TrialResult:
    """Run (or resume) one trial until ``trial.episodes``; runs in the worker (a local process
    or a Ray task). Raises ``CampaignError`` (or the run store's, the rig's and the strategy's
    errors) with a one-line message."""
    from explore.episode import EpisodeConfig
    from explore.explorer import Explorer
    from explore.rig import RigConfig, make_rig
    from explore.store import RunStore, RunStoreError, atomic_write_text
    from explore.strategies import make_strategy

    _check_campaign(trial)
    check_rig_calibration(trial.rig)
    path = Path(trial.run_dir)
    started = time.time()
    host, pid = socket.gethostname(), os.getpid()
    with ExitStack() as held:  # unwinds in reverse: the store closes before the lock goes
        store = None
        if RunStore.is_run(path):
            held.enter_context(_trial_lock(path))
            store = RunStore.open(path)
            held.callback(store.close)
            config = store.config
            config["episodes"] = trial.episodes
            config["rig"]["options"].update(trial.rig.get("options", {}))  # ports change
        else:
            config = _new_config(trial)
        # strategy and rig before a new run folder exists: a bad name leaves nothing
        strat = make_strategy(config["strategy"]["name"], **config["strategy"]["options"])
        rig = make_rig(RigConfig(**config["rig"]))
        if store is None:
            try:
                store = RunStore.create(path, config)
            except RunStoreError as exc:
                raise CampaignError(str(exc)) from exc
            held.enter_context(_trial_lock(path))
            held.callback(store.close)
        resumed_from = len(store)
        info = {"host": host, "pid": pid, "started": started, "resumed_from": resumed_from}
        atomic_write_text(path / TRIAL_FILE, json.dumps(info))
        bar = _Bar(trial, resumed_from) if progress else None
        if bar:
            held.callback(bar.close)
        explorer = Explorer(
            rig, strat, store, seed=int(config["seed"]),
            episode_config=EpisodeConfig(**config.get("episode", {})),
            on_episode=bar.update if bar else None,
        )  # fmt: skip
        explorer.run(trial.episodes)
        rows = explorer.metrics.rows
        cells = int(rows[-1]["ball_cells"]) if rows else 0  # type: ignore[arg-type]
        result = TrialResult(
            trial.strategy, trial.seed, len(store), cells, resumed_from, host, pid, started,
            time.time(),
        )  # fmt: skip
        atomic_write_text(path / TRIAL_FILE, json.dumps(dataclasses.asdict(result)))
        return result


class _Bar:
    """tqdm bar of one trial, fed with the explorer's ``Progress``."""

    def __init__(self, trial: Trial, initial: int) -> None:
        from tqdm import tqdm

        self.bar = tqdm(total=trial.episodes, initial=initial, unit="ep", mininterval=2.0,
                        desc=f"{trial.strategy} s{trial.seed}", file=sys.stderr)  # fmt: skip

    def update(self, p: Any) -> None:
        self.bar.n = p.episode
        self.bar.set_postfix(cells=p.ball_cells, phase=p.phase, refresh=False)
        self.bar.update(0)

    def close(self) -> None:
        self.bar.close()


def run_one(
    run_dir: str, strategy: str, options: dict[str, Any], seed: int, episodes: int, progress: bool
) -> tuple[str, int, int]:
    """Run (or resume) one (strategy, seed) on the twin in ``run_dir``, outside any campaign;
    returns (strategy, seed, final ball cells)."""
    r = run_trial(Trial(str(run_dir), strategy, seed, episodes, dict(options)), progress)
    return r.strategy, r.seed, r.cells


# ---- backends --------------------------------------------------------------------------------
def report_line(r: TrialResult) -> str:
    """One line on a finished trial (progress output)."""
    resumed = f", resumed at {r.resumed_from}" if r.resumed_from else ""
    return (f"done: {r.strategy} seed {r.seed}: {r.episodes} episodes, {r.cells} ball cells "
            f"({r.host} pid {r.pid}, {r.wall_s:.1f} s{resumed})")  # fmt: skip


def failure_message(failed: list[tuple[Trial, str]], finished: int) -> str:
    """The one-line error of a campaign some of whose trials failed."""
    first, why = failed[0]
    more = f" and {len(failed) - 1} more" if len(failed) > 1 else ""
    return (f"{len(failed)} trial(s) failed ({first.label}: {why}{more}); {finished} finished "
            "and are kept; rerun the same command to resume the others")  # fmt: skip


def _one_line(exc: BaseException) -> str:
    text = str(exc).strip() or type(exc).__name__
    return text.splitlines()[0]


PR_SET_PDEATHSIG = 1  # linux/prctl.h


def die_with_parent(parent: int) -> None:
    """Worker initialiser: end this process with SIGTERM when the campaign process that
    started it dies (Linux ``prctl(PR_SET_PDEATHSIG)``), so a campaign killed with SIGKILL
    leaves no worker running its trial on: its run folders are resumed by the next run of the
    command. SIGTERM turns a hardware arm's torque off (``robot.arm``); a twin run just stops
    (its history is crash-safe). Elsewhere than Linux it does nothing."""
    if not sys.platform.startswith("linux"):
        return
    import ctypes
    import signal

    libc = ctypes.CDLL(None, use_errno=True)
    if libc.prctl(PR_SET_PDEATHSIG, int(signal.SIGTERM), 0, 0, 0) != 0:
        return  # not allowed here: the worker runs on as before
    if os.getppid() != parent:  # the parent died before the signal was armed
        os._exit(1)


def run_trial_in_worker(trial: Trial, progress: bool, parent: int) -> TrialResult:
    """``run_trial`` in a pool worker. A SIGTERM inside the trial (the campaign died, see
    ``die_with_parent``) ends it as an exception once torque is off; the pool would then
    report it to nobody and wait for more work forever, so the worker exits instead."""
    try:
        return run_trial(trial, progress)
    finally:
        if os.getppid() != parent:
            os._exit(1)


def run_local(trials: list[Trial], settings: BackendSettings) -> list[TrialResult]:
    """Run trials in this process (jobs 1) or in ``jobs`` spawned processes; a failed trial
    does not stop the others. Raises ``CampaignError`` at the end if any failed."""
    jobs = settings.jobs or 1
    results: list[TrialResult] = []
    failed: list[tuple[Trial, str]] = []

    def done(trial: Trial, get: Callable[[], TrialResult]) -> None:
        try:
            r = get()
        except Exception as exc:  # one trial's failure is reported, the others go on
            failed.append((trial, _one_line(exc)))
            return
        results.append(r)
        if settings.progress:
            print(report_line(r), file=sys.stderr)

    if jobs <= 1 or len(trials) <= 1:
        for t in trials:
            done(t, lambda t=t: run_trial(t, settings.progress))
    else:
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor

        ctx = multiprocessing.get_context("spawn")  # no inherited GL or torch thread state
        with ProcessPoolExecutor(
            max_workers=jobs, mp_context=ctx, initializer=die_with_parent,
            initargs=(os.getpid(),),
        ) as pool:  # fmt: skip
            futures = [(t, pool.submit(run_trial_in_worker, t, settings.progress, os.getpid()))
                       for t in trials]  # fmt: skip
            for t, f in futures:
                done(t, f.result)
    if failed:
        raise CampaignError(failure_message(failed, len(results)))
    return results


def load_backend(name: str) -> Callable[[list[Trial], BackendSettings], list[TrialResult]]:
    target = BACKENDS.get(name)
    if target is None:
        raise CampaignError(f"unknown backend {name!r}; choose one of {', '.join(BACKENDS)}")
    module_name, func_name = target.split(":")
    return getattr(importlib.import_module(module_name), func_name)


# ---- planning --------------------------------------------------------------------------------
def option_target(key: str) -> tuple[str | None, str]:
    """``"NAME:KEY"`` -> (NAME, KEY), an option for that strategy only; ``"KEY"`` -> (None,
    KEY), one for every goal-exploration strategy."""
    target, scoped, option = key.rpartition(":")
    return (target, option) if scoped else (None, key)


def strategy_options(
    name: str, models: dict[str, Path | None], common: dict[str, Any]
) -> dict[str, Any]:
    """Options of one strategy in a campaign: every plain ``KEY`` of ``common`` (goal-exploration
    strategies, not rpe), every ``NAME:KEY`` for this strategy (e.g. ``rge-vae:latents``) and
    its model from ``models`` (flag -> path, ``MODEL_FLAGS``); raises CampaignError naming the
    command that makes a missing model."""
    opts: dict[str, Any] = {}
    for key, value in common.items():
        target, option = option_target(key)
        if target == name or (target is None and name != "rpe"):
            opts[option] = value
    from explore.strategies import MAKE_VAE

    flag = MODEL_FLAGS.get(name)
    if flag is not None:
        path = models.get(flag)
        if path is None:
            raise CampaignError(f"{name} needs --{flag} PATH; make one with: {MAKE_VAE[flag]}")
        if not path.exists():
            raise CampaignError(f"--{flag} {path}: no such file or folder; make one with: "
                                f"{MAKE_VAE[flag]}")  # fmt: skip
        opts[MODEL_OPTION[flag]] = str(path.resolve())
    return opts


def campaign_id(out: Path) -> str:
    """The id in ``out/campaign.json``, written (new) if the file is absent."""
    from explore.store import atomic_write_text

    marker = out / CAMPAIGN_FILE
    found = _read_json(marker).get("id")
    if isinstance(found, str) and found:
        return found
    out.mkdir(parents=True, exist_ok=True)
    new = uuid.uuid4().hex
    doc = {"app": "ergo-explore", "id": new, "created": time.strftime("%Y-%m-%dT%H:%M:%S%z")}
    atomic_write_text(marker, json.dumps(doc, indent=2))
    return new


def plan_trials(
    out: Path,
    strategies: list[str],
    seeds: list[int],
    episodes: int,
    options: dict[str, dict[str, Any]],
    rig: dict[str, Any],
    cid: str | None,
) -> list[Trial]:
    """The trials not finished yet. Raises CampaignError when a run folder holds another run
    (strategy, seed or rig) than the campaign's."""
    from explore.store import RunStore, RunStoreError

    todo = []
    for s in strategies:
        for seed in seeds:
            run_dir = out / s / f"seed-{seed}"
            if RunStore.is_run(run_dir):
                try:
                    cfg = RunStore.read_meta(run_dir)["config"]
                except RunStoreError as exc:
                    raise CampaignError(str(exc)) from exc
                held = (cfg["strategy"]["name"], int(cfg["seed"]), cfg["rig"]["name"],
                        cfg["rig"]["rig_id"])  # fmt: skip
                if held != (s, seed, rig["name"], rig["rig_id"]):
                    raise CampaignError(f"{run_dir} holds another run ({held[0]}, seed {held[1]}, "
                                        f"rig {held[2]} {held[3]})")  # fmt: skip
                if final_cells(run_dir)[0] >= episodes:
                    continue  # finished
            todo.append(Trial(str(run_dir), s, seed, episodes, options[s], rig, cid,
                              trial_resources(rig)))  # fmt: skip
    return todo


def run_campaign(
    out: Path,
    strategies: list[str],
    seeds: list[int],
    episodes: int,
    jobs: int | None = None,
    models: dict[str, Path | None] | None = None,
    options: dict[str, Any] | None = None,
    progress: bool = False,
    backend: str = "local",
    ray_address: str | None = None,
    rig: dict[str, Any] | None = None,
    retries: int = DEFAULT_RETRIES,
) -> list[dict[str, Any]]:
    """Run every (strategy, seed) not finished yet on ``backend``; returns the summary rows
    (and writes ``out/summary.csv``). ``models``: representation flag ("vae", "betavae",
    "sae") -> model path, for the strategies that need one. Raises ``CampaignError``."""
    from calibration.store import CalibrationError, check_rig_id
    from explore.strategies import STRATEGIES

    for name in strategies:
        if name not in STRATEGIES:
            raise CampaignError(f"unknown strategy {name!r}; choose among {', '.join(STRATEGIES)}")
    for key in options or {}:
        target, _ = option_target(key)
        if target is not None and target not in strategies:
            raise CampaignError(
                f"--option {key}: {target!r} is not a strategy of this campaign "
                f"({', '.join(strategies)})"
            )
    rig = dict(TWIN_RIG) if rig is None else rig
    if is_physical(rig):
        try:
            check_rig_id(rig["rig_id"])
        except CalibrationError as exc:
            raise CampaignError(str(exc)) from exc
        if backend == "local" and (jobs or 1) > 1:
            raise CampaignError(
                f"rig {rig['rig_id']!r} is one arm: the local backend runs its trials one at a "
                "time (--jobs 1), or use --backend ray"
            )
    if ray_address is not None and backend != "ray":
        raise CampaignError("--ray-address goes with --backend ray")
    run = load_backend(backend)
    opts = {s: strategy_options(s, models or {}, options or {}) for s in strategies}
    out = out.resolve()  # workers elsewhere see the same absolute path
    todo = plan_trials(out, strategies, seeds, episodes, opts, rig, campaign_id(out))
    if todo:
        run(todo, BackendSettings(jobs, progress, ray_address, retries))
    return write_summary(out, strategies, seeds)


# ---- results ---------------------------------------------------------------------------------
def final_cells(run_dir: Path) -> tuple[int, int]:
    """(episodes, final ball cells) of a run from its metrics.csv; (0, 0) when absent."""
    from explore.metrics import read_metrics

    path = run_dir / "metrics.csv"
    if not path.exists():
        return 0, 0
    m = read_metrics(path)
    if len(m["episode"]) == 0:
        return 0, 0
    return len(m["episode"]), int(m["ball_cells"][-1])


def welch_vs_baseline(cells: Any, baseline: Any) -> tuple[float, float]:
    """Welch's t-test (unequal variances) of final cells against the baseline's (RPE), two-sided.

    Returns (t, p); NaN when either side has fewer than 2 seeds or both have no spread.
    """
    import warnings

    import numpy as np
    from scipy import stats

    a, b = np.asarray(cells, dtype=float), np.asarray(baseline, dtype=float)
    if len(a) < 2 or len(b) < 2 or (a.std() == 0 and b.std() == 0):
        return float("nan"), float("nan")
    with warnings.catch_warnings():  # one side without spread (all seeds equal) is fine here
        warnings.simplefilter("ignore", RuntimeWarning)
        res = stats.ttest_ind(a, b, equal_var=False)
    return float(res.statistic), float(res.pvalue)


def write_summary(out: Path, strategies: list[str], seeds: list[int]) -> list[dict[str, Any]]:
    """Final ball cells per strategy over seeds, and Welch's t-test of each against ``rpe``
    (when the campaign has it) -> ``out/summary.csv``; returns the rows."""
    import numpy as np

    rows = []
    finals = {}
    for s in strategies:
        per_seed = [final_cells(out / s / f"seed-{seed}") for seed in seeds]
        finals[s] = np.array([c for _, c in per_seed], dtype=float)
        cells = finals[s]
        rows.append({
            "strategy": s,
            "seeds": len(seeds),
            "episodes": min(n for n, _ in per_seed),
            "cells_mean": round(float(cells.mean()), 2),
            "cells_std": round(float(cells.std(ddof=1)) if len(cells) > 1 else 0.0, 2),
            "cells_per_seed": " ".join(str(int(c)) for c in cells),
        })  # fmt: skip
    for r in rows:
        t, pval = (float("nan"), float("nan"))
        if "rpe" in finals and r["strategy"] != "rpe":
            t, pval = welch_vs_baseline(finals[r["strategy"]], finals["rpe"])
        r["welch_t_vs_rpe"] = round(t, 3)
        r["welch_p_vs_rpe"] = round(pval, 4)
    with open(out / "summary.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    return rows


def format_table(rows: list[dict[str, Any]]) -> str:
    head = (
        f"{'strategy':<14} {'episodes':>8} {'ball cells (mean ± std)':>24} {'Welch p vs rpe':>15}"
    )
    lines = [head + "  per seed"]
    for r in rows:
        cells = f"{r['cells_mean']:.1f} ± {r['cells_std']:.1f}"
        p = r.get("welch_p_vs_rpe", float("nan"))
        ptxt = "" if p != p else f"{p:.4f}"  # NaN: no test (rpe itself, or too few seeds)
        lines.append(
            f"{r['strategy']:<14} {r['episodes']:>8} {cells:>24} {ptxt:>15}  {r['cells_per_seed']}"
        )
    return "\n".join(lines)
