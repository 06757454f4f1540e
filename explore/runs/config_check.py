"""Validation of a run's config (``run.json``'s ``config`` object, or a new run's flags).

A hand-edited or foreign ``run.json`` must give one line naming the field and what was
expected, before anything is built or written, instead of a traceback half-way into the run.

    validate_run_config(config, where="runs/x/run.json")   # raises RunConfigError

``RunConfigError`` is a ``RunStoreError``, so ``ergo explore`` already turns it into its
one-line ``ergo: error: ...``.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

from explore.runs.store import RunStoreError

# Seeds feed numpy.random.default_rng([seed, episode]): non-negative integers only.
MAX_SEED = 2**63 - 1
# Rendered frame side, pixels: below 16 the tracker has nothing to see, above 2048 a software
# render takes seconds (guesses, on the safe side).
RENDER_SIDE = (16, 2048)
# Episode timing bounds (guesses: wide enough for any sensible rig, narrow enough to catch
# a typo such as rate_hz 4000 or a negative wait).
EPISODE_BOUNDS: dict[str, tuple[float, float]] = {
    "rate_hz": (1.0, 1000.0),
    "reset_s": (0.0, 60.0),
    "settle_speed": (0.0, 10.0),
    "arm_settle_speed": (0.0, 10.0),
    "settle_max_s": (0.0, 600.0),
    "settle_check_s": (0.001, 60.0),
    "obs_size": (8, 1024),
}


class RunConfigError(RunStoreError):
    """A run config field is missing, of the wrong type or out of range (one line)."""


def _fail(where: str, field: str, why: str) -> None:
    raise RunConfigError(f"{where}: field '{field}' {why}")


def _is_int(v: Any) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _is_number(v: Any) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)


def _obj(where: str, parent: dict[str, Any], key: str, path: str) -> dict[str, Any]:
    if key not in parent:
        _fail(where, path, "is missing")
    v = parent[key]
    if not isinstance(v, dict):
        _fail(where, path, f"must be an object, got {type(v).__name__} {v!r}")
    return v


def _name(where: str, parent: dict[str, Any], path: str, table: dict[str, Any]) -> str:
    v = parent.get("name")
    if not isinstance(v, str) or v not in table:
        _fail(where, f"{path}.name", f"must be one of {', '.join(sorted(table))}, got {v!r}")
    return v


def _check_rig_options(where: str, opts: dict[str, Any]) -> None:
    if "render_size" in opts:
        v = opts["render_size"]
        lo, hi = RENDER_SIDE
        if (
            not isinstance(v, list | tuple)
            or len(v) != 2
            or not all(_is_int(x) and lo <= x <= hi for x in v)
        ):
            _fail(
                where, "config.rig.options.render_size",
                f"must be [height, width], integers in [{lo}, {hi}], got {v!r}",
            )  # fmt: skip
    for key in ("port", "can"):
        if key in opts and (not isinstance(opts[key], str) or not opts[key]):
            _fail(
                where, f"config.rig.options.{key}", f"must be a non-empty string, got {opts[key]!r}"
            )
    for key in ("baud", "bitrate"):
        if key in opts and not (_is_int(opts[key]) and opts[key] > 0):
            _fail(
                where, f"config.rig.options.{key}", f"must be a positive integer, got {opts[key]!r}"
            )
    if "camera" in opts and not (
        (isinstance(opts["camera"], str) and opts["camera"])
        or (_is_int(opts["camera"]) and opts["camera"] >= 0)
    ):
        _fail(
            where, "config.rig.options.camera",
            f"must be a device index, path or URL, got {opts['camera']!r}",
        )  # fmt: skip


def _check_episode(where: str, ep: dict[str, Any]) -> None:
    from explore.runs.episode import EpisodeConfig

    known = {f.name for f in dataclasses.fields(EpisodeConfig)}
    for key, value in ep.items():
        path = f"config.episode.{key}"
        if key not in known:
            _fail(where, path, f"is unknown; known: {', '.join(sorted(known))}")
        lo, hi = EPISODE_BOUNDS.get(key, (-math.inf, math.inf))
        if key == "obs_size":
            if not _is_int(value) or not lo <= value <= hi:
                _fail(where, path, f"must be an integer in [{lo:g}, {hi:g}], got {value!r}")
        elif not _is_number(value) or not lo <= value <= hi:
            _fail(where, path, f"must be a number in [{lo:g}, {hi:g}], got {value!r}")


def validate_run_config(config: Any, where: str = "run.json") -> None:
    """Raise ``RunConfigError`` naming the first bad field of a run config; None if valid.

    Args:
        config: the ``config`` object of ``run.json`` (or a new run's config).
        where: what to name in the message (the file's path).
    """
    from explore.rigs.rig import RIG_FACTORIES
    from explore.learner.strategies import STRATEGIES

    where = str(where)
    if not isinstance(config, dict):
        _fail(where, "config", f"must be an object, got {type(config).__name__}")
    rig = _obj(where, config, "rig", "config.rig")
    _name(where, rig, "config.rig", RIG_FACTORIES)
    rig_id = rig.get("rig_id", "twin")
    if not isinstance(rig_id, str) or not rig_id:
        _fail(where, "config.rig.rig_id", f"must be a non-empty string, got {rig_id!r}")
    opts = rig.get("options", {})
    if not isinstance(opts, dict):
        _fail(where, "config.rig.options", f"must be an object, got {type(opts).__name__}")
    _check_rig_options(where, opts)

    strategy = _obj(where, config, "strategy", "config.strategy")
    _name(where, strategy, "config.strategy", STRATEGIES)
    s_opts = strategy.get("options", {})
    if not isinstance(s_opts, dict):
        _fail(where, "config.strategy.options", f"must be an object, got {type(s_opts).__name__}")

    seed = config.get("seed")
    if not _is_int(seed) or not 0 <= seed <= MAX_SEED:
        _fail(where, "config.seed", f"must be an integer in [0, 2**63-1], got {seed!r}")
    episodes = config.get("episodes")
    if not _is_int(episodes) or episodes < 1:
        _fail(where, "config.episodes", f"must be an integer >= 1, got {episodes!r}")
    if "episode" in config:
        _check_episode(where, _obj(where, config, "episode", "config.episode"))
