"""The input files a run depends on, recorded in its ``run.json`` and checked on resume.

A run's episodes are only comparable with each other when the files that shaped them stayed
the same: a physical rig's calibration files (joints, camera, arena:
``explore.rigs.hardware.calibration_files``) and the goal-space model of a learned strategy
(the ``vae`` or ``sae`` folder's weights and config, ``vision.vae`` / ``vision.spatial_ae``).
``run.json`` holds them as ``"inputs": [{"kind", "path", "sha256"}, ...]`` (kind ``joints``,
``camera``, ``arena`` or ``model``). A resume compares them with the files the resumed config
names now, by kind (and file name for a model; a path that moved with the same contents is
the same input) and refuses, in one line naming what changed and the override, a run whose
files changed, appeared or disappeared. With the override the resume goes on and ``run.json``
keeps the record it replaced under ``inputs_before``, with the episode count at the change.

A ``run.json`` without the record (made before it existed, or a new run killed between
writing its ``run.json`` and the record: ``open_run`` writes it just after) resumes as
before; the files it uses from then on are recorded then.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from explore.learner.strategies.registry import MODELS
from explore.runs.config import RunConfig
from explore.runs.layout import INPUTS_KEY, RUN_FILE
from explore.runs.store import RunStore, RunStoreError
from plumbing.files import atomic_write

BEFORE = "inputs_before"  # run.json's key of the records replaced by an allowed change
ALLOW_FLAG = "--allow-changed-inputs"  # ergo explore's override


class InputsChanged(RunStoreError):
    """A resumed run's input files differ from those it started with (one line)."""


def _model_files(option: str, path: str) -> list[Path]:
    """The files of a goal-space model the strategy option ``option`` (``vae`` or ``sae``)
    names: its folder's weights and config (a ``.pt`` path names its folder, as the loaders
    take it)."""
    if option == "vae":
        from vision.vae import CONFIG_FILE, MODEL_FILE
    else:
        from vision.spatial_ae import CONFIG_FILE, MODEL_FILE
    given = Path(path).expanduser()
    folder = given.parent if given.suffix == ".pt" else given
    return [folder / MODEL_FILE, folder / CONFIG_FILE]


# strategy options that name a goal-space model (the registry's models: vae, sae)
MODEL_OPTIONS = tuple(dict.fromkeys(model.option for model in MODELS))


def current_inputs(config: RunConfig) -> list[dict[str, str]]:
    """The input files the run ``config`` describes reads now, with their hashes (files that
    do not exist are left out: a rig without a calibration of some kind, a model not made)."""
    from calibration.store import file_sha256
    from explore.rigs.hardware import calibration_files

    files = calibration_files(config.rig)
    for option in MODEL_OPTIONS:
        named = config.strategy.options.get(option)
        if isinstance(named, str) and named:
            files += [("model", f) for f in _model_files(option, named) if f.is_file()]
    return [
        {"kind": kind, "path": str(path.resolve()), "sha256": file_sha256(path)}
        for kind, path in files
    ]


def _key(entry: dict[str, str]) -> str:
    """What an input is, whatever its path: its kind, and its file name for a model."""
    kind = entry["kind"]
    return f"{kind} {Path(entry['path']).name}" if kind == "model" else kind


def describe_changes(before: list[dict[str, str]], now: list[dict[str, str]]) -> list[str]:
    """What differs between two records, in words (empty when the same files)."""
    old = {_key(e): e for e in before}
    new = {_key(e): e for e in now}
    out = []
    for key in sorted(old.keys() | new.keys()):
        a, b = old.get(key), new.get(key)
        if a is None:
            out.append(f"{key} {b['path']} appeared")
        elif b is None:
            out.append(f"{key} {a['path']} is gone")
        elif a["sha256"] != b["sha256"]:
            out.append(
                f"{key} {b['path']} changed (sha256 {a['sha256'][:12]} -> {b['sha256'][:12]})"
            )
    return out


def record_inputs(store: RunStore, config: RunConfig) -> None:
    """Write the inputs ``config`` reads now into the run's ``run.json`` (a new run, or a run
    recorded before the record existed)."""
    _write(store, {**store.meta, INPUTS_KEY: current_inputs(config)})


def check_inputs(store: RunStore, config: RunConfig, allow_changed: bool = False) -> str | None:
    """On resume: compare the inputs ``config`` reads now with those ``run.json`` recorded.

    Returns:
        a note for the user (one line) when something was recorded or an allowed change
        was, else None.

    Raises:
        InputsChanged: they differ and ``allow_changed`` is False (nothing is written).
    """
    now = current_inputs(config)
    recorded = store.meta.get(INPUTS_KEY)
    if not isinstance(recorded, list):
        _write(store, {**store.meta, INPUTS_KEY: now})
        return (
            f"{store.path}: run.json had no record of its input files (an older run): "
            f"recorded the {len(now)} it uses now"
        )
    changes = describe_changes(recorded, now)
    if not changes:
        return None
    what = "; ".join(changes)
    if not allow_changed:
        raise InputsChanged(
            f"{store.path}: its input files changed since it started ({what}): its episodes "
            f"would mix two calibrations or models; restore them, or resume anyway with "
            f"ergo explore --resume {store.path} {ALLOW_FLAG}"
        )
    history = list(store.meta.get(BEFORE) or [])
    history.append({"until_episode": len(store), INPUTS_KEY: recorded})
    _write(store, {**store.meta, INPUTS_KEY: now, BEFORE: history})
    return f"{store.path}: resumed with changed input files ({what}); run.json keeps the old record"


def _write(store: RunStore, meta: dict[str, Any]) -> None:
    """Replace ``run.json`` atomically (as ``RunStore.create`` writes it) and the store's copy."""
    atomic_write(store.path / RUN_FILE, json.dumps(meta, indent=2, sort_keys=True))
    store.meta = meta
