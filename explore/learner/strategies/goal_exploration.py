"""Goal exploration (IMGEP): random goals (RGE) or modular goals by interest (MGE).

Every episode after a bootstrap of random parameters:
1. choose a module (RGE: the whole goal space; MGE: by learning-progress interest);
2. sample a goal in that module (option ``goals``: uniformly in the bounds of the outcomes seen
   so far, uniformly in the fixed box [-1, 1]^d, or, for latent spaces, N(0, 1) clipped at
   +-2.5 as in the paper), or choose one where the reached outcomes are sparse (option
   ``goal_sampling``, ``explore.learner.goal_sampling``);
3. play the parameters of the nearest (context, outcome) in the module's database, plus
   Gaussian noise ("explore"), or without noise ("exploit", which alone updates interests).

Two schedules of explore and exploit episodes (option ``schedule``):
- ``"random"`` (the default): every episode chooses its own module and goal, and is an exploit
  episode with probability ``exploit`` (0.2 MGE, 0 RGE);
- ``"cycle"``: the original ArmBalls campaign's (``mge_efr.py``, ``exploactors.py``,
  docs/armballs.md): one module and goal per ``n_explore`` + 1 episodes: ``n_explore`` noisy
  variations of the parameters nearest to the goal when it was chosen, then one noise-free
  episode with the parameters nearest to it after them (the exploit); only the exploit's
  (goal, outcome) enters the interest's goal history, one entry per goal.

A rig whose scene resets before every episode (``Scene.resets``: ArmBalls) gives no context:
the database is indexed by outcomes alone, as the original's.

All randomness comes from the generator passed to ``propose``; the state is a deterministic
function of the records given to ``update`` (a resumed run replays them).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from explore.learner.dmp import N_PARAMS
from explore.learner.experience import Experience, Observation
from explore.learner.goal_sampling import N_DRAWS, make_sampler
from explore.learner.goal_spaces import (
    EngineeredGoalSpace,
    GoalSpace,
    LatentGoalSpace,
    spatial_goal_space,
)
from explore.learner.interest import ModuleInterest
from explore.learner.meta_policy import MetaPolicy
from explore.learner.scene import Scene
from explore.learner.strategies.base import (
    Description,
    Proposal,
    Strategy,
    StrategyError,
)
from explore.learner.strategies.goal_options import (  # noqa: F401
    BOOTSTRAP,
    BOX,
    EXPLOIT_MGE,
    LATENT_FORMS,
    N_EXPLORE,
    NORMAL_CLIP,
    RANDOM_EPISODES_RIG,
    SIGMA_RIG,
    STALL_WINDOW,
    STILL_FRACTION,
    EngineeredOptions,
    GoalExplorationOptions,
    LatentOptions,
    SpatialOptions,
)

# the options and their constants, importable from here as before they moved
from plumbing.fixed_order import distance, norm


class GoalExploration(Strategy):
    """Goal exploration in the goal space of a representation (RGE, or MGE by default with
    ``modular_default``); every {rge, mge} x {efr, vae, betavae, sae} strategy is this class
    with its registry entry's (``modular_default``, ``representation``).

    Args:
        modular_default: MGE unless the option ``modular`` says otherwise.
        representation: a key of ``REPRESENTATIONS`` (its options and its goal space), or
            None for a subclass with its own ``Options`` and ``make_space`` (rge-online).
        n_params, scene, name, options: as ``Strategy``'s.
    """

    name = "goal-exploration"
    Options: type = GoalExplorationOptions
    needs_ball = True

    def __init__(
        self,
        n_params: int = N_PARAMS,
        *,
        scene: Scene,
        modular_default: bool = False,
        representation: str | None = None,
        **options: Any,
    ) -> None:
        self.modular_default = modular_default
        self.representation = None if representation is None else representation_of(representation)
        if self.representation is not None:
            self.Options = self.representation.Options
        super().__init__(n_params, scene=scene, **options)
        s = self.settings
        self.bootstrap = s.bootstrap
        self.sigma = s.sigma
        self.modular = self.modular_default if s.modular is None else s.modular
        self.exploit = (EXPLOIT_MGE if self.modular else 0.0) if s.exploit is None else s.exploit
        self.random_episodes = s.random_episodes
        self.stall_window = s.stall_window
        self.stall_random = s.stall_random
        self.still = 0  # consecutive episodes whose outcome stayed at its context
        self.goals = s.goals  # the goal distribution of "uniform" sampling
        self.goal_sampling = s.goal_sampling
        self.window = s.window
        self.random_choice = s.random_choice
        self.cycle = s.schedule == "cycle"
        self.cycle_length = s.n_explore + 1
        self.n_seen = 0
        self.n_goal_episodes = 0  # goal-directed episodes learnt from (the cycle's position)
        # module, goal, base (None: uniform parameters, ``one_outcome="random"``)
        self._goal_cycle: tuple[int, np.ndarray, np.ndarray | None] | None = None
        self.space: GoalSpace | None = None
        self._last_latent: np.ndarray | None = None  # latent spaces: context of the next move
        self._pending: list[Experience] = []  # records seen before the space exists
        self._init_space(self.make_space())

    @classmethod
    def options_for(cls, representation: str | None = None, **params: Any) -> type:
        return cls.Options if representation is None else representation_of(representation).Options

    # ---- hooks for subclasses ----------------------------------------------------------------
    def make_space(self) -> GoalSpace | None:
        """The goal space (the representation's), or None while it does not exist yet (online
        representations)."""
        if self.representation is None:
            raise NotImplementedError(f"{type(self).__name__} has no representation")
        return self.representation.make_space(self)

    # ---- state -------------------------------------------------------------------------------
    def _init_space(self, space: GoalSpace | None) -> None:
        self.space = space
        if space is None:
            return
        dims = [len(m) for m in space.modules]
        context_dim = 0 if self.scene.resets else space.context_dim
        s = self.settings
        self.policy = MetaPolicy(
            context_dim, dims, self.n_params, ties=s.ties, context_weight=s.context_weight
        )
        self.low = [np.full(d, np.inf) for d in dims]
        self.high = [np.full(d, -np.inf) for d in dims]
        # bounds of the outcome's part that describes what the context does (stall_window)
        self._still_low = np.full(context_dim, np.inf)
        self._still_high = np.full(context_dim, -np.inf)
        self.interest = ModuleInterest(
            dims,
            self.window,
            self.random_choice,
            average=s.interest,
            competence=s.competence,
            start=s.interest_start,
        )
        self.sampler = make_sampler(s.goal_sampling, dims, s.goal_misses, context_dim)
        if isinstance(space, LatentGoalSpace):
            self._last_latent = np.zeros(space.dim)

    def _context(self, engineered: Callable[[], np.ndarray]) -> np.ndarray:
        """The context part of an inverse model's input: none where the scene puts the ball
        back for every episode, the last latent code in a learned space, else
        ``engineered()`` (the engineered space's context features)."""
        assert self.space is not None
        if self.scene.resets:
            return np.zeros(0)
        if isinstance(self.space, LatentGoalSpace):
            return self._last_latent  # type: ignore[return-value]
        return engineered()

    def _record_context(self, record: Experience) -> np.ndarray:
        return self._context(lambda: self.space.context(record))  # type: ignore[union-attr]

    def _propose_context(self, context: Observation) -> np.ndarray:
        return self._context(
            lambda: self.space.context_of(context.ball, context.distractor)  # type: ignore[union-attr]
        )

    def update(self, record: Experience) -> None:
        self.n_seen += 1
        if self.space is None:
            self._pending.append(record)
            self.after_pending()
            return
        self._learn(record)

    def after_pending(self) -> None:
        """Called after a record was kept while there is no goal space yet."""

    def _learn(self, record: Experience) -> None:
        space = self.space
        assert space is not None
        context = self._record_context(record)
        outcome = space.outcome(record)
        parts = space.module_outcomes(outcome)
        directed = record.module >= 0 and record.kind in ("explore", "exploit")
        if directed:
            k = record.module
            if k >= len(parts) or len(record.goal) != len(space.modules[k]):
                raise StrategyError(
                    f"episode {record.episode} has module {k} and a goal of size "
                    f"{len(record.goal)}: not recorded by this strategy's goal space"
                )
            if self.cycle and self.n_goal_episodes % self.cycle_length == 0:
                # a new goal: its noisy episodes vary the parameters nearest to it now (before
                # this record joins the database), as ``propose`` computed them
                base = None if self._plays_random(k) else self.policy.nearest_theta(
                    k, context, record.goal)  # fmt: skip
                self._goal_cycle = (k, np.asarray(record.goal, dtype=float), base)
            self.n_goal_episodes += 1
        self.policy.add(context, parts, record.theta)
        self._count_still(context, outcome)
        for k, o in enumerate(parts):
            if o is not None:
                self.low[k] = np.minimum(self.low[k], o)
                self.high[k] = np.maximum(self.high[k], o)
        if self.sampler is not None:
            goal = record.goal if directed else None
            k = record.module if directed else -1
            self.sampler.learn(parts, k, goal, self.low[k], self.high[k], context)
        if directed:
            k = record.module
            exploit = record.kind == "exploit"
            self.interest.update(
                k, record.goal, parts[k], exploit, self._scale(k),
                remember=exploit or not self.cycle,
            )  # fmt: skip
        if outcome is not None and isinstance(space, LatentGoalSpace):
            self._last_latent = outcome

    def _count_still(self, context: np.ndarray, outcome: np.ndarray | None) -> None:
        """Update ``still``, the run of consecutive episodes whose outcome stayed where its
        context was: the outcome's first ``len(context)`` coordinates (the same features as
        the context: the ball's before and after in an engineered space, the code of the
        scene before and after in a learned one) within ``STILL_FRACTION`` of the diagonal
        of their bounds so far. An episode without an outcome (the ball unseen) leaves it."""
        if self.stall_window == 0 or outcome is None or len(context) == 0:
            return
        o = np.asarray(outcome, dtype=float)[: len(context)]
        if not np.all(np.isfinite(o)) or not np.all(np.isfinite(context)):
            return
        self._still_low = np.minimum(self._still_low, np.minimum(o, context))
        self._still_high = np.maximum(self._still_high, np.maximum(o, context))
        diag = norm(self._still_high - self._still_low)
        moved = distance(o, context) > STILL_FRACTION * diag
        self.still = 0 if moved else self.still + 1

    def random_share(self) -> float:
        """The probability that the next episode after the bootstrap plays random parameters:
        ``random_episodes``, or ``stall_random`` after ``stall_window`` unchanged outcomes."""
        if self.stall_window and self.still >= self.stall_window:
            return max(self.random_episodes, self.stall_random)
        return self.random_episodes

    def _plays_random(self, module: int) -> bool:
        """Whether ``module`` answers with uniform parameters (``one_outcome="random"`` and
        every outcome it recorded the same)."""
        return self.settings.one_outcome == "random" and not self.policy.varied(module)

    def _scale(self, module: int) -> float:
        """Competence scale of a module: the diagonal of its outcome bounds (at least 1e-6)."""
        span = self.high[module] - self.low[module]
        span = np.where(np.isfinite(span), span, 0.0)
        return max(norm(span), 1e-6)

    # ---- proposals ---------------------------------------------------------------------------
    def _random(self, rng: np.random.Generator) -> Proposal:
        return Proposal(theta=rng.uniform(-1.0, 1.0, self.n_params), kind="random")

    def sample_goal(
        self, module: int, rng: np.random.Generator, context: np.ndarray | None = None
    ) -> np.ndarray:
        """A goal in ``module``: chosen by the ``goal_sampling`` sampler where it has a
        candidate (``context``: the inverse model's context now, its reachability guard),
        else one draw of ``goals``: uniform in the bounds seen so far, uniform in [-1, 1]^d
        (``box``), or clipped N(0, 1) (``normal``)."""
        if self.sampler is not None:
            lo, hi = self.low[module], self.high[module]
            drawn = None
            if self.sampler.mode == "sparse":
                drawn = np.stack([self._draw_goal(module, rng) for _ in range(N_DRAWS)])
            goal = self.sampler.goal(module, rng, lo, hi, context, drawn)
            if goal is not None:
                return goal
        return self._draw_goal(module, rng)

    def _draw_goal(self, module: int, rng: np.random.Generator) -> np.ndarray:
        """One draw of the goal distribution ``goals`` in ``module``."""
        d = len(self.low[module])
        if self.goals == "normal":
            return np.clip(rng.normal(0.0, 1.0, d), -NORMAL_CLIP, NORMAL_CLIP)
        if self.goals == "box":
            return rng.uniform(-BOX, BOX, d)
        return rng.uniform(self.low[module], self.high[module])

    def propose(self, context: Observation, rng: np.random.Generator) -> Proposal:
        if self.space is None or self.n_seen < self.bootstrap:
            return self._random(rng)
        share = self.random_share()
        if share > 0 and rng.random() < share:
            return self._random(rng)
        if self.cycle:
            return self._propose_in_cycle(context, rng)
        module = self.interest.choose(rng) if self.modular else 0
        if self.policy.size(module) == 0:
            return self._random(rng)
        ctx = self._propose_context(context)
        goal = self.sample_goal(module, rng, ctx)
        exploit = self.exploit > 0 and rng.random() < self.exploit
        if self._plays_random(module):
            theta = rng.uniform(-1.0, 1.0, self.n_params)
        else:
            theta = self.policy.infer(module, ctx, goal, rng, 0.0 if exploit else self.sigma)
        return Proposal(
            theta=theta, goal=goal, module=module, kind="exploit" if exploit else "explore"
        )

    def _propose_in_cycle(self, context: Observation, rng: np.random.Generator) -> Proposal:
        """The next episode of the goal cycle (module doc, ``schedule="cycle"``)."""
        position = self.n_goal_episodes % self.cycle_length
        ctx = self._propose_context(context)
        if position == 0:
            module = self.interest.choose(rng) if self.modular else 0
            if self.policy.size(module) == 0:
                return self._random(rng)
            goal = self.sample_goal(module, rng, ctx)
            base = None if self._plays_random(module) else self.policy.nearest_theta(
                module, ctx, goal)  # fmt: skip
        else:
            assert self._goal_cycle is not None
            module, goal, base = self._goal_cycle
        if position < self.cycle_length - 1:
            if base is None:  # a module that has seen one outcome (``one_outcome="random"``)
                noisy = rng.uniform(-1.0, 1.0, self.n_params)
            elif self.sigma > 0:
                noisy = base + rng.normal(0.0, self.sigma, self.n_params)
            else:
                noisy = base
            return Proposal(np.clip(noisy, -1.0, 1.0), goal.copy(), module, "explore")
        if self._plays_random(module):
            theta = rng.uniform(-1.0, 1.0, self.n_params)
        else:
            theta = self.policy.nearest_theta(module, ctx, goal)
        return Proposal(np.clip(theta, -1.0, 1.0), goal.copy(), module, "exploit")

    def phase(self) -> str:
        if self.space is None or self.n_seen < self.bootstrap:
            return "bootstrap"
        return "mge" if self.modular else "rge"

    def describe(self, record: Experience) -> Description | None:
        space = self.space
        if space is None:
            return None
        outcome = space.outcome(record)
        full = np.full(space.dim, np.nan)
        goal = full.copy()
        k = record.module
        if 0 <= k < len(space.modules) and len(record.goal) == len(space.modules[k]):
            goal[space.modules[k]] = record.goal
        return Description(
            context=np.asarray(self._record_context(record), dtype=float),
            outcome=full if outcome is None else np.asarray(outcome, dtype=float),
            goal=goal,
        )


def engineered_space(strategy: GoalExploration) -> GoalSpace:
    """EFR: the ball's engineered features on the rig's scene (options: ``EngineeredOptions``);
    the tool tip as a module by default when modular."""
    s = strategy.settings
    hand = strategy.modular if s.hand_module is None else s.hand_module
    distractor = strategy.scene.distractor if s.distractor is None else s.distractor
    try:
        space = EngineeredGoalSpace(s.form, hand, distractor, scene=strategy.scene)
    except ValueError as exc:
        raise StrategyError(f"{strategy.name}: {exc}") from None
    if s.flat:
        space.modules = [np.arange(space.dim)]
    return space


def _load_model(strategy: GoalExploration, option: str, load: Callable[[str], Any]) -> Any:
    """The model the strategy's ``option`` names, loaded by ``load``; a StrategyError (one
    line) when the option is missing (naming how to make one: the registry entry's
    ``Model.recipe``) or the model cannot be read."""
    path = getattr(strategy.settings, option)
    if not path:
        from explore.learner.strategies.registry import STRATEGIES

        entry = STRATEGIES.get(strategy.name)
        model = entry.model if entry is not None else None
        how = f" (make one with: {model.recipe})" if model is not None else ""
        raise StrategyError(f"{strategy.name} needs option {option}=PATH{how}")
    from vision.vae import VaeError

    try:
        return load(path)
    except (VaeError, FileNotFoundError) as exc:
        raise StrategyError(f"{strategy.name}: {exc}") from exc


def vae_space(strategy: GoalExploration) -> GoalSpace:
    """The latent space of a VAE trained beforehand (options: ``LatentOptions``)."""
    from vision.vae import load_vae

    vae = _load_model(strategy, "vae", load_vae)
    path = strategy.settings.vae
    return latent_space(vae, strategy.modular, strategy.settings.latents, path)


def check_latents(latents: str, where: str) -> str:
    """The ``latents`` option, or StrategyError naming ``where`` if it is not a known form."""
    if latents not in LATENT_FORMS:
        raise StrategyError(
            f"{where}: latents must be one of {', '.join(LATENT_FORMS)}, got {latents!r}"
        )
    return latents


def latent_space(
    vae: Any, modular: bool, latents: str = "raw", where: Any = "the VAE"
) -> LatentGoalSpace:
    """A ``LatentGoalSpace`` over a loaded ``vision.vae.Vae``: its raw latent means, or
    (``latents="zscore"``) the means z-scored with the statistics saved with the VAE."""
    check_latents(latents, str(where))
    stats = None
    if latents == "zscore":
        cfg = vae.config
        if cfg.latent_mean is None or cfg.latent_std is None:
            raise StrategyError(
                f"{where} has no latent statistics (trained before 2026-11-23): run the same "
                "`ergo vae train` command again on its folder to add them"
            )
        stats = (cfg.latent_mean, cfg.latent_std)
    try:
        return LatentGoalSpace(
            vae.encode_bgr, vae.config.latent_dim, vae.config.kl_per_latent, modular=modular,
            zscore=stats,
        )  # fmt: skip
    except ValueError as exc:
        raise StrategyError(f"{where}: {exc}") from exc


def spatial_space(strategy: GoalExploration) -> GoalSpace:
    """The image positions of a spatial autoencoder's features (options: ``SpatialOptions``):
    its live features' (x, y), the whole code for RGE, one module per feature for MGE. Goals
    are uniform in the bounds reached (the code has no prior to sample from); the context is
    the previous outcome's code."""
    from vision.spatial_ae import load_sae

    sae = _load_model(strategy, "sae", load_sae)
    path = strategy.settings.sae
    if sae.config.code_std is None:
        raise StrategyError(f"{path} has no code statistics: train it with `ergo sae train`")
    if strategy.goals == "normal":
        raise StrategyError(f"{strategy.name}: goals must be uniform (the code has no prior)")
    return spatial_goal_space(
        sae.encode_bgr, sae.config.code_std, strategy.modular, sae.config.code_corr
    )


@dataclass(frozen=True)
class Representation:
    """What a goal-exploration strategy explores in.

    Attributes:
        Options: the strategy's options dataclass with it.
        make_space: the strategy -> its goal space (a ``StrategyError`` for a bad option or a
            missing model).
    """

    Options: type
    make_space: Callable[[GoalExploration], GoalSpace | None]


LATENT = Representation(LatentOptions, vae_space)
#: representation key (a strategy name's suffix, ``registry.STRATEGIES``) -> Representation;
#: a VAE and a beta-VAE differ only in the model trained beforehand (the registry's ``Model``).
REPRESENTATIONS: dict[str, Representation] = {
    "efr": Representation(EngineeredOptions, engineered_space),
    "vae": LATENT,
    "betavae": LATENT,
    "sae": Representation(SpatialOptions, spatial_space),
}


def representation_of(key: str) -> Representation:
    """``REPRESENTATIONS[key]``; a ``StrategyError`` (one line) for an unknown key."""
    found = REPRESENTATIONS.get(key)
    if found is None:
        raise StrategyError(
            f"unknown representation {key!r}; choose one of {', '.join(REPRESENTATIONS)}"
        )
    return found
