"""One run's configuration, typed: ``RunConfig`` (rig, strategy, seed, episodes, episode timing),
read from and written to ``run.json``'s ``config`` object.

``RunConfig.from_dict(config, where)`` checks everything before anything is built or written
and raises ``RunConfigError`` with one line naming the field and what was expected: a hand-edited
or foreign ``run.json``, or a new run's flags. The rig's and the strategy's options are checked
against their own ``Options`` dataclasses (unknown keys refused with the list of known ones).
``run.json`` keeps storing names and the options as given, so existing run folders keep
loading; with one exception, the options whose default changed after runs had been made
(``CHANGED_STRATEGY_DEFAULTS``): a new run writes them out (``RunConfig.with_defaults_pinned``),
and a run's config read back (``RunConfig.of_run``) gives the ones it lacks the value it was
made with, so a run resumed, replayed or exported under a newer version does what it did.

``RunConfigError`` is a ``RunStoreError``, so ``ergo explore`` already turns it into its
one-line ``ergo: error: ...``.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from explore.rigs.episodes import EpisodeConfig
from explore.rigs.rig import RIGS, RigConfig
from explore.runs.store import RunStoreError
from plumbing.fields import Fields, is_int

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
TOP_LEVEL = ("rig", "strategy", "seed", "episodes", "episode", "warm_start")
# Strategy options whose default changed after runs had been made without the key in their
# run.json: option -> the value those runs were made with.
CHANGED_STRATEGY_DEFAULTS: dict[str, Any] = {
    # 10 since 2026-12-03 (goal exploration's random parameters in a stall, docs/results.md
    # F8); the runs before had no such behaviour, which stall_window 0 is
    "stall_window": 0,
}


class RunConfigError(RunStoreError):
    """A run config field is missing, of the wrong type or out of range (one line)."""


# The flags of ``ergo explore`` that set a field of a new run's config, by the field's path:
# a command line's error names the flag the user typed, not the field of run.json.
FLAGS = {
    "config.rig.name": "--rig",
    "config.rig.rig_id": "--rig-id",
    "config.rig.options": "--rig-option",
    "config.strategy.name": "--strategy",
    "config.strategy.options": "--strategy-option",
    "config.seed": "--seed",
    "config.episodes": "--episodes",
    "config.warm_start": "--warm-start",
}
# Rig options that have a flag of their own (``robot/bus_flags.py``, ``--camera``).
OPTION_FLAGS = {"port": "--port", "baud": "--baud", "can": "--can", "bitrate": "--bitrate",
                "camera": "--camera"}  # fmt: skip


def flag_of(path: str) -> str:
    """How ``ergo explore``'s error names a new run's field at ``path``: the flag that sets it
    (``config.strategy.name`` -> ``--strategy``, ``config.rig.options.render_size`` ->
    ``--rig-option render_size``, ``config.rig.options.port`` -> ``--port``), else the field
    (``field 'config.episode.rate_hz'``: no flag sets it)."""
    if path in FLAGS:
        return FLAGS[path]
    parent, _, key = path.rpartition(".")
    if parent == "config.rig.options" and key in OPTION_FLAGS:
        return OPTION_FLAGS[key]
    if parent in ("config.rig.options", "config.strategy.options"):
        return f"{FLAGS[parent]} {key}"
    return f"field {path!r}"


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
        warm_start: the folder of a run made elsewhere (the twin) whose episodes seed this
            run's learner, absolute (``explore/runs/prior.py``); None: none. Written into
            ``run.json`` only when given.
    """

    rig: RigConfig = field(default_factory=RigConfig)
    strategy: StrategyConfig = field(default_factory=StrategyConfig)
    seed: int = DEFAULT_SEED
    episodes: int = DEFAULT_EPISODES
    episode: EpisodeConfig = field(default_factory=EpisodeConfig)
    warm_start: str | None = None

    def to_dict(self) -> dict[str, Any]:
        """The ``run.json`` form: names, options as given, every episode setting."""
        out = {
            "rig": self.rig.to_dict(),
            "strategy": self.strategy.to_dict(),
            "seed": self.seed,
            "episodes": self.episodes,
            "episode": dataclasses.asdict(self.episode),
        }
        if self.warm_start is not None:
            out["warm_start"] = self.warm_start
        return out

    def with_overrides(
        self, episodes: int | None = None, rig_options: dict[str, Any] | None = None
    ) -> RunConfig:
        """A copy with another episode count and/or rig options added on top of the run's own
        (ports and cameras change between sessions). Not checked: see ``checked``."""
        rig = self.rig
        if rig_options:
            rig = dataclasses.replace(rig, options={**rig.options, **rig_options}, calibration=None)
        return dataclasses.replace(
            self, rig=rig, episodes=self.episodes if episodes is None else episodes
        )

    def with_defaults_pinned(self) -> RunConfig:
        """A new run's config with each ``CHANGED_STRATEGY_DEFAULTS`` option its strategy takes
        and that was not given written out at today's default (into its ``run.json``)."""
        return self._with_missing_options(new=True)

    def as_made(self) -> RunConfig:
        """A made run's config with each ``CHANGED_STRATEGY_DEFAULTS`` option its strategy
        takes and its ``run.json`` lacks at the value it was made with (the old default)."""
        return self._with_missing_options(new=False)

    def _with_missing_options(self, new: bool) -> RunConfig:
        from explore.learner.strategies import STRATEGIES

        options_class = STRATEGIES.options_class(self.strategy.name)
        if not dataclasses.is_dataclass(options_class):
            return self
        defaults = {f.name: f.default for f in dataclasses.fields(options_class)}
        missing = {
            key: defaults[key] if new else old
            for key, old in CHANGED_STRATEGY_DEFAULTS.items()
            if key in defaults and key not in self.strategy.options
        }
        if not missing:
            return self
        options = {**self.strategy.options, **missing}
        return dataclasses.replace(self, strategy=StrategyConfig(self.strategy.name, options))

    @classmethod
    def of_run(cls, config: Any, where: Any = "run.json") -> RunConfig:
        """``from_dict`` for a made run's ``run.json`` config, ``as_made``: what the run was
        made with, whatever today's defaults are. Raises ``RunConfigError`` as ``from_dict``."""
        return cls.from_dict(config, where).as_made()

    def checked(
        self, where: str = "command line", label: Callable[[str], str] | None = None
    ) -> RunConfig:
        """Itself, checked as ``from_dict`` checks a ``run.json`` (``RunConfigError``).

        Args:
            label: how the line names a bad field; with one, the line starts with it (``ergo
                explore`` gives ``flag_of``: the flag that set the field).
        """
        return RunConfig.from_dict(self.to_dict(), "" if label else where, label=label)

    @classmethod
    def from_dict(
        cls, config: Any, where: Any = "run.json", label: Callable[[str], str] | None = None
    ) -> RunConfig:
        """Check ``config`` (``run.json``'s ``config`` object, or a new run's) and build it.

        Args:
            label: how the line names a bad field (``plumbing.fields.Fields``'s ``label``).

        Raises:
            RunConfigError: naming the first bad field, in one line.
        """
        top = Fields(str(where), config, RunConfigError, "config", label=label)
        top.only(TOP_LEVEL)
        rig = top.sub("rig")
        rig_name = rig.one_of("name", RIGS)
        rig_id = rig.data.get("rig_id", RigConfig.rig_id)
        if not isinstance(rig_id, str) or not rig_id:
            rig.fail("rig_id", f"must be a non-empty string, got {rig_id!r}")
        rig_opts = _options(rig, RIGS.load(rig_name).Options)

        from explore.learner.strategies import STRATEGIES

        strategy = top.sub("strategy")
        name = strategy.one_of("name", STRATEGIES)
        s_opts = _options(strategy, STRATEGIES.options_class(name))

        seed = top.data.get("seed")
        if not is_int(seed) or not 0 <= seed <= MAX_SEED:
            top.fail("seed", f"must be an integer in [0, 2**63-1], got {seed!r}")
        episodes = top.data.get("episodes")
        if not is_int(episodes) or episodes < 1:
            top.fail("episodes", f"must be an integer >= 1, got {episodes!r}")
        episode = _episode(top.sub("episode")) if "episode" in config else EpisodeConfig()
        warm_start = top.data.get("warm_start")
        if warm_start is not None and (not isinstance(warm_start, str) or not warm_start):
            top.fail("warm_start", f"must be a run folder's path, got {warm_start!r}")
        return cls(
            rig=RigConfig(rig_name, rig_id, rig_opts),
            strategy=StrategyConfig(name, s_opts),
            seed=seed,
            episodes=episodes,
            episode=episode,
            warm_start=warm_start,
        )


def _options(parent: Fields, options_class: type) -> dict:
    """``parent``'s ``options`` (default {}), checked against ``options_class``; returned as
    given."""
    from explore.options import OptionsError, parse_options

    opts = parent.data.get("options", {})
    if not isinstance(opts, dict):
        parent.fail("options", f"must be an object, got {type(opts).__name__}")
    try:
        parse_options(options_class, opts, parent.path)
    except OptionsError as exc:
        parent.fail(f"options.{exc.key}" if exc.key else "options", exc.reason)
    return dict(opts)


def _episode(ep: Fields) -> EpisodeConfig:
    ep.only(sorted(f.name for f in dataclasses.fields(EpisodeConfig)))
    for key in ep.data:
        lo, hi = EPISODE_BOUNDS.get(key, (-math.inf, math.inf))
        if key == "obs_size":
            ep.integer(key, lo, hi)
        else:
            ep.number(key, lo, hi)
    return EpisodeConfig(**ep.data)
