"""Planning a campaign: the strategies' options, the campaign's id, the trials not finished yet,
and ``run_campaign``, which runs them on a backend and writes the summary.

A campaign is a folder ``CAMPAIGN/STRATEGY/seed-S`` of ordinary run folders
(explore/runs/store.py) plus ``CAMPAIGN/campaign.json`` (its id) and ``CAMPAIGN/summary.csv``.
Resumable whatever dies: finished trials are skipped, unfinished ones resume from their run
folder (the history is append-only and fsync'ed per episode, so a killed worker loses at most
the episode in flight; on the twin the resumed history equals an uninterrupted one).
"""

from __future__ import annotations

import json
import time
import uuid
from pathlib import Path
from typing import Any

from explore.campaigns.backends import DEFAULT_RETRIES, BackendSettings, load_backend
from explore.campaigns.stats import final_cells, write_summary
from explore.campaigns.trial import (
    CAMPAIGN_FILE,
    CampaignError,
    Trial,
    is_physical,
    read_json,
    trial_resources,
)
from explore.rigs.rig import RigConfig
from plumbing.registry import did_you_mean


def option_target(key: str) -> tuple[str | None, str]:
    """``"NAME:KEY"`` -> (NAME, KEY), an option for that strategy only; ``"KEY"`` -> (None,
    KEY), one for every goal-exploration strategy."""
    target, scoped, option = key.rpartition(":")
    return (target, option) if scoped else (None, key)


def strategy_options(
    name: str, models: dict[str, Path | None], common: dict[str, Any], preset: str | None = None
) -> dict[str, Any]:
    """Options of one strategy in a campaign: the ``preset``'s for it
    (``explore.learner.presets``), then every plain ``KEY`` of ``common`` (to the strategies
    whose registry entry takes the goal-exploration options: not rpe), every ``NAME:KEY`` for
    this strategy (e.g. ``rge-vae:latents``) and its model from ``models`` (flag -> path, the
    entry's ``Model``); raises CampaignError naming the command that makes a missing model, an
    unknown strategy or preset."""
    from explore.learner.strategies import STRATEGIES, StrategyError

    try:
        entry = STRATEGIES.entry(name)
    except StrategyError as exc:
        raise CampaignError(str(exc)) from None
    opts: dict[str, Any] = {}
    if preset is not None:
        from explore.learner.strategies.registry import preset_options

        try:
            opts.update(preset_options(preset, name))
        except StrategyError as exc:
            raise CampaignError(str(exc)) from None
    for key, value in common.items():
        target, option = option_target(key)
        if target == name or (target is None and entry.goal_exploration):
            opts[option] = value
    model = entry.model
    if model is not None:
        path = models.get(model.flag)
        if path is None:
            raise CampaignError(f"{name} needs --{model.flag} PATH; make one with: {model.recipe}")
        if not path.exists():
            raise CampaignError(f"--{model.flag} {path}: no such file or folder; make one with: "
                                f"{model.recipe}")  # fmt: skip
        opts[model.option] = str(path.resolve())
    return opts


def campaign_id(out: Path) -> str:
    """The id in ``out/campaign.json``, written (new) if the file is absent.

    Two processes starting one campaign at once agree on one id: the new file is written whole
    under a name of this process's own, then linked into place only if no other process's is
    there already (``os.link`` refuses an existing name); the loser reads the winner's id.
    """
    import os

    from plumbing.files import atomic_write, temporary_name

    marker = out / CAMPAIGN_FILE
    found = read_json(marker).get("id")
    if isinstance(found, str) and found:
        return found
    out.mkdir(parents=True, exist_ok=True)
    new = uuid.uuid4().hex
    doc = {"app": "ergo-explore", "id": new, "created": time.strftime("%Y-%m-%dT%H:%M:%S%z")}
    own = temporary_name(marker.with_name(marker.name + ".new"))
    atomic_write(own, json.dumps(doc, indent=2))
    try:
        os.link(own, marker)
    except FileExistsError:
        found = read_json(marker).get("id")
        if not (isinstance(found, str) and found):
            raise CampaignError(
                f"{marker}: no campaign id in it (damaged?): move it away"
            ) from None
        return found
    finally:
        own.unlink(missing_ok=True)
    return new


_UNSET = object()  # an option a run's config does not hold


def plan_trials(
    out: Path,
    strategies: list[str],
    seeds: list[int],
    episodes: int,
    options: dict[str, dict[str, Any]],
    rig: dict[str, Any],
    cid: str | None,
    warm_start: Path | None = None,
) -> list[Trial]:
    """The trials not finished yet. Raises CampaignError when a run folder holds another run
    (strategy, seed or rig) than the campaign's, or a run made with another value of an
    option given now (a run keeps the options it started with; the model paths are not
    compared: the run checks its model's file itself)."""
    from explore.learner.strategies import STRATEGIES
    from explore.runs.config import RunConfig
    from explore.runs.prior import prior_folder
    from explore.runs.store import RunStore, RunStoreError

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
                model = STRATEGIES.entry(s).model
                kept = RunConfig.of_run(cfg, run_dir).strategy.options
                for key, value in options[s].items():
                    if (model is None or key != model.option) and kept.get(key, _UNSET) != value:
                        was = kept.get(key, "its default")
                        raise CampaignError(
                            f"{run_dir} was made with {key} = {was}, not {value}: a run keeps "
                            "the options it started with (give them as they were, or another "
                            "--out for new ones)"
                        )
                if final_cells(run_dir)[0] >= episodes:
                    continue  # finished
            prior = None if warm_start is None else str(prior_folder(warm_start, s, seed))
            todo.append(Trial.of(str(run_dir), s, seed, episodes, options[s], rig, cid,
                                 trial_resources(rig), prior))  # fmt: skip
    return todo


def check_options(
    strategy: str, options: dict[str, Any], rig: dict[str, Any], episodes: int
) -> None:
    """Raise ``CampaignError`` naming ``--option KEY`` when ``strategy`` refuses one of its
    ``options`` (an unknown key, a wrong type), as each trial's run config would."""
    from explore.runs.config import RunConfig, RunConfigError, flag_of

    def label(path: str) -> str:
        parent, _, key = path.rpartition(".")
        return f"--option {key}" if parent == "config.strategy.options" else flag_of(path)

    config = {"rig": rig, "strategy": {"name": strategy, "options": options}, "seed": 0,
              "episodes": episodes}  # fmt: skip
    try:
        RunConfig.from_dict(config, "", label=label)
    except RunConfigError as exc:
        raise CampaignError(f"{strategy}: {exc}") from None


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
    preset: str | None = None,
    warm_start: Path | None = None,
) -> list[dict[str, Any]]:
    """Run every (strategy, seed) not finished yet on ``backend``; returns the summary rows
    (and writes ``out/summary.csv``). ``models``: representation flag ("vae", "betavae",
    "sae") -> model path, for the strategies that need one; ``preset``: a named preset of
    strategy options (``explore.learner.presets``), under ``options``; ``warm_start``: a twin
    run or campaign whose episodes warm each trial (``explore.runs.prior.prior_folder``).
    Raises ``CampaignError``."""
    from explore.learner.strategies import STRATEGIES
    from explore.rigs.hardware import check_rig_id
    from explore.rigs.rig import RigError

    for name in strategies:
        if name not in STRATEGIES:
            raise CampaignError(
                f"unknown strategy {name!r}{did_you_mean(name, STRATEGIES)}; "
                f"choose among {', '.join(STRATEGIES)}"
            )
    for key in options or {}:
        target, _ = option_target(key)
        if target is not None and target not in strategies:
            raise CampaignError(
                f"--option {key}: {target!r} is not a strategy of this campaign "
                f"({', '.join(strategies)})"
            )
    rig = RigConfig().to_dict() if rig is None else rig
    if is_physical(rig):
        try:
            check_rig_id(RigConfig(rig["name"], rig["rig_id"], dict(rig.get("options", {}))))
        except RigError as exc:
            raise CampaignError(str(exc)) from exc
        if backend == "local" and (jobs or 1) > 1:
            raise CampaignError(
                f"rig {rig['rig_id']!r} is one arm: the local backend runs its trials one at a "
                "time (--jobs 1), or use --backend ray"
            )
    if ray_address is not None and backend != "ray":
        raise CampaignError("--ray-address goes with --backend ray")
    run = load_backend(backend)
    opts = {s: strategy_options(s, models or {}, options or {}, preset) for s in strategies}
    for s in strategies:  # a bad option: one line naming --option, before anything is written
        check_options(s, opts[s], rig, episodes)
    out = out.resolve()  # workers elsewhere see the same absolute path
    todo = plan_trials(out, strategies, seeds, episodes, opts, rig, campaign_id(out), warm_start)
    if todo:
        run(todo, BackendSettings(jobs, progress, ray_address, retries))
    return write_summary(out, strategies, seeds)
