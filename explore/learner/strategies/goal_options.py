"""The options of the goal-exploration strategies (``goal_exploration.GoalExploration``) and
the constants behind their defaults, each with where it comes from.

``GoalExplorationOptions`` holds what every goal-exploration strategy takes; each
representation adds its own (``EngineeredOptions``, ``LatentOptions``, ``SpatialOptions``;
rge-online's in ``online.py``). Unknown keys and bad values are refused in one line
(``explore.options.parse_options``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from explore.learner.goal_sampling import GOAL_MISSES, GoalSampling
from explore.learner.interest import RANDOM_CHOICE, START_PROGRESS, WINDOW
from explore.options import BadOption

BOOTSTRAP = 100  # paper: 100-400 random episodes in the simulations
EXPLOIT_MGE = 0.2  # paper: about 1 episode in 5 is a noise-free exploit episode (MGE)
NORMAL_CLIP = 2.5  # paper: latent goals N(0, 1) clipped at +-2.5
BOX = 1.0  # goals="box": uniform in [-BOX, BOX]^d, the original's engineered goal bounds
N_EXPLORE = 4  # schedule="cycle": noisy episodes per goal before its exploit (original: 4)
LATENT_FORMS = ("raw", "zscore")
# The original rig's settings (the original implementation, docs/facts.md), the defaults here
# because the ball is not reset between episodes, on the rig as on the twin. With the paper's
# simulation settings (sigma 0.05, no random episodes), rge-efr replayed bootstrap motions that
# never touched the ball where it lay in 2 of 3 seeds (0 touches in 1400 goal episodes) and
# reached fewer cells than RPE (docs/results_stalls.md).
SIGMA_RIG = 0.2  # exploration noise in the [-1, 1] parameter space, original rig
RANDOM_EPISODES_RIG = 0.1  # share of random motor babbling episodes after the bootstrap, rig
# An outcome less than this fraction of a diagonal away from its context counts as "unchanged"
# (option ``stall_window``), the diagonal of the box holding every context and outcome seen so
# far (in the goal space's coordinates). A guess, under what a 1 cm ball move (the rig's
# ``MOVED_THRESHOLD``) gives in the engineered wrap-safe features (1.9% of their diagonal along
# the ring, 14% across it). On rge-efr seed 0 (1500 twin episodes, 2026-12-03) it called 24
# episodes changed that the rig called not moved (ball moves under 1 cm) and none the other
# way; in the spatial autoencoder's code, on rge-sae seed 1 (without the option), 13 and none.
STILL_FRACTION = 0.01
# Option ``stall_window``'s default: 10 episodes that left the outcome where it was turn every
# episode into random parameters until one changes it (``stall_random`` 1). Chosen from F7
# (docs/results.md): in the stalls, where the ball lay against the outer wall, goal episodes
# moved it in 0.6-1.9% of the episodes and random parameters in 5-8%. 10 is a guess; measured
# with it on development seeds 0-7 (docs/results.md, F8): stalls in 1 of 16 rge-efr and
# rge-sae runs (8 of 16 without), 11-24% of the episodes after the bootstrap played random
# parameters (9-11% without).
STALL_WINDOW = 10
# Option ``prior_context`` (rule 5 of explore/learner/prior.py): a prior entry answers only a
# query whose context lies within this fraction of the diagonal of the prior's contexts from its
# own; 0 (the default): any context. Off by default: in one process on development stand-ins
# 340-347 and over the bus on final stand-ins 210-212, 0.1 kept out the prior's answers that
# mostly miss the ball (docs/warm_start.md, "Where the prior costs") but gave no more ball cells
# at 300 episodes, and fewer at 100 over the bus.
PRIOR_CONTEXT = 0.0


@dataclass(frozen=True)
class GoalExplorationOptions:
    """Options of every goal-exploration strategy.

    Attributes:
        bootstrap: random episodes before goal exploration (default 100).
        sigma: exploration noise in the [-1, 1] parameter space (default 0.2, the original
            rig; the paper's simulations used 0.05).
        exploit: probability of a noise-free exploit episode (default 0.2 MGE, 0 RGE), in the
            random schedule (the cycle has one exploit per goal).
        random_episodes: probability of a random-parameter episode after the bootstrap
            (default 0.1, the original rig; 0 in the paper's simulations).
        goals: "uniform" in the outcome bounds seen so far (default), "box" uniform in the fixed
            box [-1, 1]^d (the original's engineered goals), or "normal" N(0, 1) clipped at
            +-2.5 (latent spaces).
        modular: choose modules by interest (MGE) instead of the whole space (RGE); default:
            the strategy's.
        window, random_choice: interest window (exploit episodes) and random module share.
        schedule: "random" (default) or "cycle" (module doc), with ``n_explore`` noisy
            episodes per goal (default 4).
        interest: "window" (default: the mean of the last ``window`` progresses) or
            "exponential" (the original's average, time constant ``window``).
        interest_start: the exponential average's starting value (default 1e-5, the
            original's). Larger, every module keeps a share of the choices until its own
            progress has been measured: a start of 0.01 is worth about 400 exploits of a
            module whose progress is noise of sd 0.5 (Arm-2-Balls' distractor), against a
            few at 1e-5 (docs/results_armballs.md, "Stalls, stopped in the long run").
        competence: "scaled" (default: distance over the module's outcome diagonal, capped at
            1) or "distance" (the original's: the distance capped at 2).
        ties: which of several equally near past episodes the inverse model replays: "first"
            (default: the earliest) or "spread" (one picked by a hash of the goal;
            ``MetaPolicy``).
        one_outcome: what a module plays while every episode it recorded had the same
            outcome: "nearest" (default: the neighbour, which is then any of them) or "random"
            (uniform parameters, explore and exploit alike: explauto's ``NonParametric``,
            the original ArmBalls campaign's inverse model).
        context_weight: factor on the context in the inverse model's nearest-neighbour
            distance (``MetaPolicy``): 1 (default) the joint (context, outcome) search; larger,
            the replayed episode started from a scene nearer the current one.
        stall_window: after this many consecutive episodes whose outcome in the goal space
            stayed where its context was (within ``STILL_FRACTION`` of the outcomes'
            diagonal), the share of random-parameter episodes becomes ``stall_random`` until
            an episode changes the outcome again (default ``STALL_WINDOW``, 10; 0: never,
            the setting of every run before 2026-12-03). Needs a context: on a scene reset
            between episodes (ArmBalls) it never acts.
        stall_random: the share of random-parameter episodes in such a stall (default 1).
        goal_sampling: how a goal is chosen in its module (``explore.learner.goal_sampling``):
            "uniform" (default, the paper's: one draw of the ``goals`` distribution),
            "density" (the least dense of candidates among the reached outcomes, after MEGA)
            "frontier" (that outcome moved one bandwidth out of the reached set) or "sparse"
            (the least dense of 10 draws of ``goals`` near the reached set). ``goals`` applies
            to "uniform" and "sparse" (and to the others' fallback when no outcome is a
            candidate).
        goal_misses: "density"'s reachability guard: a reached outcome aimed at and missed
            this many times is no longer a candidate (default 3; 0: no guard).
        prior_context: with a prior (``--warm-start``), an entry of it answers only a query
            whose context lies within this fraction of the diagonal of the prior's contexts
            from its own (rule 5 of ``explore.learner.prior``; default 0: any context).
    """

    bootstrap: int = BOOTSTRAP
    sigma: float = SIGMA_RIG
    exploit: float | None = None
    random_episodes: float = RANDOM_EPISODES_RIG
    goals: Literal["uniform", "normal", "box"] = "uniform"
    modular: bool | None = None
    window: int = WINDOW
    random_choice: float = RANDOM_CHOICE
    schedule: Literal["random", "cycle"] = "random"
    n_explore: int = N_EXPLORE
    interest: Literal["window", "exponential"] = "window"
    interest_start: float = START_PROGRESS
    competence: Literal["scaled", "distance"] = "scaled"
    ties: Literal["first", "spread"] = "first"
    one_outcome: Literal["nearest", "random"] = "nearest"
    context_weight: float = 1.0
    stall_window: int = STALL_WINDOW
    stall_random: float = 1.0
    goal_sampling: GoalSampling = "uniform"
    goal_misses: int = GOAL_MISSES
    prior_context: float = PRIOR_CONTEXT

    def __post_init__(self) -> None:
        if not self.interest_start >= 0:
            raise BadOption("interest_start", f"must be >= 0, got {self.interest_start}")
        if self.interest_start != START_PROGRESS and self.interest != "exponential":
            raise BadOption("interest_start", 'acts only with interest="exponential"')
        if not self.context_weight > 0:
            raise BadOption("context_weight", f"must be > 0, got {self.context_weight}")
        if not 0.0 <= self.prior_context < float("inf"):
            raise BadOption("prior_context", f"must be >= 0 and finite, got {self.prior_context}")
        for key in ("bootstrap", "sigma", "stall_window", "goal_misses"):
            if getattr(self, key) < 0:
                raise BadOption(key, f"must be >= 0, got {getattr(self, key)}")
        for key in ("exploit", "random_episodes", "random_choice", "stall_random"):
            p = getattr(self, key)
            if p is not None and not 0.0 <= p <= 1.0:
                raise BadOption(key, f"must be a probability, got {p}")
        for key in ("window", "n_explore"):
            if getattr(self, key) < 1:
                raise BadOption(key, f"must be at least 1, got {getattr(self, key)}")


@dataclass(frozen=True)
class EngineeredOptions(GoalExplorationOptions):
    """Goal-exploration options, and: ``form`` ("wrap-safe", "polar" or "cartesian"; default:
    the scene's, wrap-safe on the twin, cartesian on ArmBalls), ``hand_module`` (the tool tip
    as a module; default True when modular), ``distractor`` (the distractor's features as a
    module and in the context, for a scene with one; default False; null: exactly when the
    rig's scene has a distractor) and ``flat`` (every feature in one module, the original's
    RGE-EFR over (distractor, ball) as one 4-D goal; default False: RGE explores the ball's
    module, the rest in the context)."""

    form: Literal["wrap-safe", "polar", "cartesian"] | None = None
    hand_module: bool | None = None
    distractor: bool | None = False
    flat: bool = False


@dataclass(frozen=True)
class LatentOptions(GoalExplorationOptions):
    """Goal-exploration options, and: ``vae`` (the model folder or its ``.pt`` file, from
    ``ergo vae train``; required) and ``latents`` ("raw" latent means, the paper's and the
    default, or "zscore": z-scored with the means' statistics over the VAE's training data)."""

    vae: str | None = None
    latents: Literal["raw", "zscore"] = "raw"


@dataclass(frozen=True)
class SpatialOptions(GoalExplorationOptions):
    """Goal-exploration options, and ``sae``: the model folder from ``ergo sae train``
    (required)."""

    sae: str | None = None
