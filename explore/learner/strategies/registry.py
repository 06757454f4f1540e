"""The strategies, one entry each: what implements it (imported only when used, as every table of
the project: ``plumbing.registry.LazyTable``, so ``ergo --help`` imports no torch), what it is in
one line, the model it needs trained beforehand, whether the common goal-exploration options apply
to it, and its named presets (explauto's way: a model's entry and its named configurations
together).

Goal exploration is one class (``goal_exploration.GoalExploration``) parametrised by
(``modular_default``, ``representation``): the {rge, mge} x {efr, vae, betavae, sae} entries are
built by ``_goal_exploration`` from those two, not written out as classes. Run folders name a
strategy by its key here (``run.json``'s ``config.strategy.name``), never by a class.

Adding a strategy: one entry in ``STRATEGIES``.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from typing import Any

from explore.learner.dmp import N_PARAMS
from explore.learner.presets import (
    CORL2018,
    CORL2018_COMMON,
    CORL2018_ENGINEERED,
    CORL2018_LEARNED,
    CORL2018_SPATIAL,
    PRESETS,
)
from explore.learner.scene import Scene
from explore.learner.strategies.base import Strategy, StrategyError
from plumbing.registry import LazyTable, did_you_mean


@dataclass(frozen=True)
class Model:
    """A representation a strategy needs trained beforehand.

    Attributes:
        flag: its name on the command line (``ergo experiment --vae``) and the key of
            ``run_campaign``'s ``models``.
        option: the strategy option that names its folder (``vae=PATH``).
        recipe: the ``ergo`` commands that make one (shown when it is missing). The strategy's
            own error names it too, so it lives here rather than in the campaign layer.
        what: what it is, for the flag's help ("a VAE").
    """

    flag: str
    option: str
    recipe: str
    what: str = "a model"


# "vae" is the recipe of docs/results.md: a plain VAE (beta 1) collapses at CPU-sized schedules.
VAE = Model(
    "vae",
    "vae",
    "ergo dataset outcomes --n 3000 --out data/outcomes.npz && "
    "ergo vae train --data data/outcomes.npz --out models/vae --beta 10 --capacity 10 "
    "--capacity-iterations 500 --iterations 700",
    "a VAE",
)
BETAVAE = Model(
    "betavae",
    "vae",
    "ergo dataset outcomes --n 10000 --out data/outcomes.npz && "
    "ergo vae train --data data/outcomes.npz --out models/betavae --beta 4 --capacity 10",
    "a beta-VAE",
)
SAE = Model(
    "sae",
    "sae",
    "ergo dataset outcomes --n 3000 --out data/outcomes.npz && "
    "ergo sae train --data data/outcomes.npz --out models/sae",
    "a spatial autoencoder",
)
# Every model a strategy may need (``ergo experiment``'s flags, the options a run's inputs name)
MODELS = (VAE, BETAVAE, SAE)


@dataclass(frozen=True)
class StrategyEntry:
    """One strategy.

    Attributes:
        target: ``"module:Class"`` of its class, imported on use.
        summary: what it is, one line (``ergo explore --help``).
        params: keyword arguments its class takes for this entry (goal exploration:
            ``modular_default`` and ``representation``).
        model: the representation it needs trained beforehand, or None.
        goal_exploration: the common goal-exploration options apply (a campaign's plain
            ``--option KEY=VALUE`` goes to it).
        presets: preset name -> its options for this strategy (``explore.learner.presets``).
    """

    target: str
    summary: str
    params: Mapping[str, Any] = field(default_factory=dict)
    model: Model | None = None
    goal_exploration: bool = True
    presets: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)

    @property
    def engineered(self) -> bool:
        """Its goal space is a function of the record alone (no model to load)."""
        return self.params.get("representation") == ENGINEERED


ENGINEERED = "efr"
GOAL_EXPLORATION = "explore.learner.strategies.goal_exploration:GoalExploration"
# representation -> (the model it needs, the corl2018 preset's options besides the common ones)
_REPRESENTATIONS: dict[str, tuple[Model | None, Mapping[str, Any]]] = {
    ENGINEERED: (None, CORL2018_ENGINEERED),
    "vae": (VAE, CORL2018_LEARNED),
    "betavae": (BETAVAE, CORL2018_LEARNED),
    "sae": (SAE, CORL2018_SPATIAL),
}


def _goal_exploration(modular: bool, representation: str, summary: str) -> StrategyEntry:
    """The entry of ``rge-REPRESENTATION`` (``modular`` False) or ``mge-REPRESENTATION``."""
    model, corl2018 = _REPRESENTATIONS[representation]
    preset = {**CORL2018_COMMON, **corl2018}
    if representation == ENGINEERED:
        # RGE-EFR explores (distractor, ball) as one goal, MGE-EFR one module per ball
        preset["flat"] = not modular
    return StrategyEntry(
        GOAL_EXPLORATION,
        summary,
        {"modular_default": modular, "representation": representation},
        model,
        presets={CORL2018: preset},
    )


class StrategyTable(Mapping[str, StrategyEntry]):
    """name -> ``StrategyEntry``, with the classes loaded on demand (``LazyTable``: an unknown
    name, or a missing dependency, is one ``StrategyError`` line)."""

    def __init__(self, entries: Mapping[str, StrategyEntry]) -> None:
        self._entries = dict(entries)
        self._classes = LazyTable(
            "strategy", {n: e.target for n, e in self._entries.items()}, error=StrategyError
        )

    def __getitem__(self, name: str) -> StrategyEntry:
        return self._entries[name]

    def __iter__(self) -> Iterator[str]:
        return iter(self._entries)

    def __len__(self) -> int:
        return len(self._entries)

    def entry(self, name: str) -> StrategyEntry:
        """The entry of ``name``; a ``StrategyError`` (one line, the known names) if unknown."""
        found = self._entries.get(name)
        if found is None:
            raise self._classes.unknown(name)
        return found

    def load(self, name: str) -> type[Strategy]:
        """The class of ``name`` (imported now)."""
        return self._classes.load(name)

    def options_class(self, name: str) -> type:
        """The ``Options`` dataclass of ``name`` (its class's, for this entry's params)."""
        return self.load(name).options_for(**self.entry(name).params)

    def make(self, name: str, n_params: int, scene: Scene, **options: Any) -> Strategy:
        """The strategy ``name`` with ``options`` (``make_strategy``)."""
        cls = self.load(name)
        return cls(n_params, scene=scene, name=name, **self.entry(name).params, **options)


STRATEGIES = StrategyTable(
    {
        "rpe": StrategyEntry(
            "explore.learner.strategies.rpe:RandomParameterExploration",
            "random motor parameters every episode (motor babbling): the baseline",
            goal_exploration=False,
        ),
        "rge-efr": _goal_exploration(
            False,
            ENGINEERED,
            "random goals in the engineered goal space: the ball's polar coordinates",
        ),
        "mge-efr": _goal_exploration(
            True,
            ENGINEERED,
            "modular goals by learning progress: ball, and the tool tip as a module",
        ),
        "rge-vae": _goal_exploration(
            False, "vae", "random goals in a VAE's latent space (strategy option vae=MODEL)"
        ),
        "rge-betavae": _goal_exploration(False, "betavae", "rge-vae with a beta-VAE (vae=MODEL)"),
        "mge-vae": _goal_exploration(
            True,
            "vae",
            "modular goals over pairs of a VAE's latents, by learning progress (vae=MODEL)",
        ),
        "mge-betavae": _goal_exploration(True, "betavae", "mge-vae with a beta-VAE (vae=MODEL)"),
        "rge-online": StrategyEntry(
            "explore.learner.strategies.online:OnlineLatentGoalExploration",
            "2000 random episodes, then random goals in a VAE trained on their images",
            # its bootstrap is its VAE's training set (2000 by default): the preset keeps it
            presets={
                CORL2018: {
                    k: v
                    for k, v in {**CORL2018_COMMON, **CORL2018_LEARNED}.items()
                    if k != "bootstrap"
                }
            },
        ),
        "rge-sae": _goal_exploration(
            False, "sae", "random goals in a spatial autoencoder's feature positions (sae=MODEL)"
        ),
        "mge-sae": _goal_exploration(
            True, "sae", "modular goals, one module per spatial-autoencoder feature (sae=MODEL)"
        ),
    }
)


def make_strategy(name: str, n_params: int = N_PARAMS, *, scene: Scene, **options: Any) -> Strategy:
    """The strategy ``name`` with ``options``, proposing ``n_params`` parameters on a rig with
    ``scene`` (``explore.rigs.rig.rig_scene``)."""
    return STRATEGIES.make(name, n_params, scene, **options)


def preset_options(preset: str, strategy: str) -> dict[str, Any]:
    """The options ``preset`` gives ``strategy`` (its registry entry's; none for RPE). Raises
    ``StrategyError`` for an unknown preset or strategy (one line)."""
    if preset not in PRESETS:
        raise StrategyError(
            f"unknown preset {preset!r}{did_you_mean(preset, PRESETS)}; "
            f"choose one of {', '.join(PRESETS)}"
        )
    return dict(STRATEGIES.entry(strategy).presets.get(preset, {}))
