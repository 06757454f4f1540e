"""One run's configuration, typed: ``RunConfig`` (rig, strategy, seed, episodes, episode timing),
read from and written to ``run.json``'s ``config`` object.

``RunConfig.from_dict(config, where)`` checks everything before anything is built or written
and raises ``RunConfigError`` with one line naming the field and what was expected: a hand-edited
or foreign ``run.json``, or a new run's flags. The rig's and the strategy's options are checked
against their own ``Options`` dataclasses (unknown keys refused with the list of known ones).
``run.json`` keeps storing names and the options as given, so existing run folders keep
loading.

``RunConfigError`` is a ``RunStoreError``, so ``ergo explore`` already turns it into its
one-line ``ergo: error: ...``.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any

from explore.rigs.episodes import EpisodeConfig
from explore.rigs.rig import RIGS, RigConfig
from explore.runs.store import RunStoreError
from robot.registry import did_you_mean

# Seeds feed numpy.random.default_rng([seed, episode]): non-negative integers only.
MAX_SEED = 2**63 - 1
DEFAULT_SEED = 0
DEFAULT_EPISODES = 300
DEFAULT_STRATEGY = "rpe"
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
TOP_LEVEL = ("rig", "strategy", "seed", "episodes", "episode")


class RunConfigError(RunStoreError):
    """A run config field is missing, of the wrong type or out of range (one line)."""


@dataclass(frozen=True)
class StrategyConfig:
    """Which strategy and its options as given (JSON-like; the strategy's ``Options`` check
    them and supply the defaults).

    Attributes:
        name: a key of ``explore.learner.strategies.STRATEGIES``.
        options: the strategy's options, e.g. ``{"bootstrap": 100, "vae": "models/vae"}``.
    """

    name: str = DEFAULT_STRATEGY
    options: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, "options": dict(self.options)}


@dataclass(frozen=True)
class RunConfig:
    """Everything that decides what a run does (``run.json``'s ``config``).

    Attributes:
        rig: the rig (name, rig id, options).
        strategy: the strategy (name, options).
        seed: the run's seed (each episode draws from ``default_rng([seed, episode])``).
        episodes: episodes the run must hold when it ends.
        episode: episode timing.
    """

    rig: RigConfig = field(default_factory=RigConfig)
    strategy: StrategyConfig = field(default_factory=StrategyConfig)
    seed: int = DEFAULT_SEED
    episodes: int = DEFAULT_EPISODES
    episode: EpisodeConfig = field(default_factory=EpisodeConfig)

    def to_dict(self) -> dict[str, Any]:
        """The ``run.json`` form: names, options as given, every episode setting."""
        return {
            "rig": self.rig.to_dict(),
            "strategy": self.strategy.to_dict(),
            "seed": self.seed,
            "episodes": self.episodes,
            "episode": dataclasses.asdict(self.episode),
        }

    def with_overrides(
        self, episodes: int | None = None, rig_options: dict[str, Any] | None = None
    ) -> RunConfig:
        """A copy with another episode count and/or rig options added on top of the run's own
        (ports and cameras change between sessions). Not checked: see ``checked``."""
        rig = self.rig
        if rig_options:
            rig = dataclasses.replace(rig, options={**rig.options, **rig_options})
        return dataclasses.replace(
            self, rig=rig, episodes=self.episodes if episodes is None else episodes
        )

    def checked(self, where: str = "command line") -> RunConfig:
        """Itself, checked as ``from_dict`` checks a ``run.json`` (``RunConfigError``)."""
        return RunConfig.from_dict(self.to_dict(), where)

    @classmethod
    def from_dict(cls, config: Any, where: Any = "run.json") -> RunConfig:
        """Check ``config`` (``run.json``'s ``config`` object, or a new run's) and build it.

        Raises:
            RunConfigError: naming the first bad field, in one line.
        """
        where = str(where)
        if not isinstance(config, dict):
            _fail(where, "config", f"must be an object, got {type(config).__name__}")
        unknown = sorted(set(config) - set(TOP_LEVEL))
        if unknown:
            _fail(where, f"config.{unknown[0]}", f"is unknown; known: {', '.join(TOP_LEVEL)}")
        rig = _obj(where, config, "rig", "config.rig")
        rig_name = _name(where, rig, "config.rig", RIGS)
        rig_id = rig.get("rig_id", RigConfig.rig_id)
        if not isinstance(rig_id, str) or not rig_id:
            _fail(where, "config.rig.rig_id", f"must be a non-empty string, got {rig_id!r}")
        rig_opts = _options(where, rig, "config.rig", RIGS.load(rig_name).Options)

        from explore.learner.strategies import STRATEGIES

        strategy = _obj(where, config, "strategy", "config.strategy")
        name = _name(where, strategy, "config.strategy", STRATEGIES)
        s_opts = _options(where, strategy, "config.strategy", STRATEGIES.options_class(name))

        seed = config.get("seed")
        if not _is_int(seed) or not 0 <= seed <= MAX_SEED:
            _fail(where, "config.seed", f"must be an integer in [0, 2**63-1], got {seed!r}")
        episodes = config.get("episodes")
        if not _is_int(episodes) or episodes < 1:
            _fail(where, "config.episodes", f"must be an integer >= 1, got {episodes!r}")
        episode = EpisodeConfig()
        if "episode" in config:
            episode = _episode(where, _obj(where, config, "episode", "config.episode"))
        return cls(
            rig=RigConfig(rig_name, rig_id, rig_opts),
            strategy=StrategyConfig(name, s_opts),
            seed=seed,
            episodes=episodes,
            episode=episode,
        )


def _fail(where: str, path: str, why: str) -> None:
    raise RunConfigError(f"{where}: field '{path}' {why}")


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


def _name(where: str, parent: dict[str, Any], path: str, table: Any) -> str:
    v = parent.get("name")
    if not isinstance(v, str) or v not in table:
        _fail(
            where,
            f"{path}.name",
            f"must be one of {', '.join(sorted(table))}, got {v!r}{did_you_mean(v, table)}",
        )
    return v


def _options(where: str, parent: dict[str, Any], path: str, options_class: type) -> dict:
    """``parent["options"]`` (default {}), checked against ``options_class``; returned as given."""
    from explore.options import OptionsError, parse_options

    opts = parent.get("options", {})
    if not isinstance(opts, dict):
        _fail(where, f"{path}.options", f"must be an object, got {type(opts).__name__}")
    try:
        parse_options(options_class, opts, path)
    except OptionsError as exc:
        _fail(where, f"{path}.options.{exc.key}" if exc.key else f"{path}.options", exc.reason)
    return dict(opts)


def _episode(where: str, ep: dict[str, Any]) -> EpisodeConfig:
    known = [f.name for f in dataclasses.fields(EpisodeConfig)]
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
    return EpisodeConfig(**ep)
