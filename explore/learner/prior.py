"""A prior for goal exploration: the episodes of a run made elsewhere (the twin) that seed a
strategy's inverse model and goals, kept apart from its own episodes and replaced by them.

The rule (docs/warm_start.md says why):

1. **The inverse model looks in both, the nearer wins.** For a goal in a module, the arm's
   own nearest (context, outcome) and the prior's nearest one still in play are compared in the
   same distance (``MetaPolicy``'s, the context weighted: the fixed-order squared distance of
   ``plumbing.fixed_order``, the same bits on both sides); the prior's answers only when it is
   strictly nearer. Its parameters are then played as the strategy plays its own (plus its
   noise on an explore episode, none on an exploit one).
2. **A prior entry answers once.** The arm's episode that played it retires it (in every
   module: the twin episode's parameters are then tried on the arm, whose own outcome for them
   joins the arm's database).
3. **Where the arm has been, its own outcomes rule.** A prior entry within ``REACH_FRACTION``
   of the diagonal of the prior's points (per module) of an outcome the arm produced is retired.
4. **Goals are drawn over the prior's reach too**: the strategy's outcome bounds start at the
   prior's (they only grow with the arm's own), and **the prior's episodes count towards the
   bootstrap** (random episodes before goal exploration): a prior of at least ``bootstrap``
   episodes starts the arm on goals from its first episode.
5. **Optionally, a prior entry answers only from a scene like its own.** With the strategy's
   option ``prior_context`` > 0, only entries whose context lies within that fraction of the
   diagonal of the prior's contexts of the query's context take part in rule 1: a twin
   episode's parameters push a ball where the twin's ball was, and played with the arm's ball
   elsewhere they mostly miss it (docs/warm_start.md, "Where the prior costs", which also says
   why it is off by default). 0 (default), or a prior whose contexts are all the same: any
   context.

The prior never enters the strategy's interests (the arm's own progress only), its stall count,
nor any count of episodes seen. All of it is a deterministic function of the prior and of the
arm's records given to ``update``: ``Prior.before_update`` (called with each record just before
``strategy.update``, on replay too) works out again which prior entry answered the record's
query, from the state the strategy had when it proposed it.

Supported: goal exploration with its random schedule (``schedule="random"``) and a goal space
made when the strategy is (the engineered and learned ones; not ``rge-online``).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from explore.learner.experience import Experience
from explore.learner.meta_policy import MetaPolicy
from explore.learner.strategies.base import Strategy, StrategyError
from plumbing.fixed_order import norm, sq_distances

# Rule 3's radius, a fraction of the diagonal of the prior's points in a module's (context,
# outcome) space. A guess: about one cell of the 30 x 30 metric along one axis (1/30 = 0.033).
REACH_FRACTION = 0.03
DIRECTED = ("explore", "exploit")


@dataclass
class PriorAnswer:
    """A prior entry that answered an arm episode's query (``Prior.before_update``).

    Attributes:
        episode: the arm's episode.
        kind: its kind ("explore": the entry's parameters plus noise; "exploit": as they were).
        prior_episode: the prior run's episode whose parameters were played.
        prior_context_ball, prior_ball: the ball (x, y) before and after that episode in the
            prior run, shape (2,), in the scene's unit (NaN: unseen).
    """

    episode: int
    kind: str
    prior_episode: int
    prior_context_ball: np.ndarray
    prior_ball: np.ndarray


@dataclass
class _ModulePrior:
    """One module's prior entries: points (n, context_dim + d) in the policy's (weighted)
    coordinates, their parameters (n, n_params), which prior record each came from (n,), and
    which are still in play (n,); ``context_dim`` and ``context_fraction`` (rule 5: 0, none)."""

    points: np.ndarray
    thetas: np.ndarray
    source: np.ndarray
    context_dim: int = 0
    context_fraction: float = 0.0
    alive: np.ndarray = field(init=False)
    radius: float = field(init=False)
    context_radius: float = field(init=False)

    def __post_init__(self) -> None:
        self.alive = np.ones(len(self.points), dtype=bool)
        self.radius = self.context_radius = 0.0
        if len(self.points):
            span = self.points.max(axis=0) - self.points.min(axis=0)
            self.radius = REACH_FRACTION * norm(span)
            self.context_radius = self.context_fraction * norm(span[: self.context_dim])

    def nearest_sq(self, q: np.ndarray) -> tuple[int, float]:
        """The nearest entry in play to ``q`` among those whose context is within
        ``context_radius`` of ``q``'s (rule 5; all when it is 0), lowest index of ties, and its
        squared distance (fixed order, as the arm's index measures it); (-1, inf) when none
        is."""
        live = np.flatnonzero(self.alive)
        if len(live) and self.context_radius > 0:
            c = self.context_dim
            near = np.sqrt(sq_distances(self.points[live, :c], q[:c])) <= self.context_radius
            live = live[near]
        if not len(live):
            return -1, np.inf
        sq = sq_distances(self.points[live], q)
        j = int(np.argmin(sq))
        return int(live[j]), float(sq[j])


class WarmPolicy(MetaPolicy):
    """A ``MetaPolicy`` (the arm's own database, as before) that also answers from the prior's
    entries still in play (rules 1 and 3 of the module doc).

    Args:
        own: the strategy's policy, empty (its settings are taken over).
        modules: per module, the prior's points, parameters and source records.
    """

    def __init__(self, own: MetaPolicy, modules: Sequence[_ModulePrior]) -> None:
        if any(own.size(k) for k in range(len(own.module_dims))):
            raise ValueError("a prior is attached before the strategy learns anything")
        super().__init__(
            own.context_dim, own.module_dims, own.n_params, ties=own.ties,
            context_weight=own.context_weight,
        )  # fmt: skip
        self.prior = list(modules)
        self.retired_by_reach = 0

    def _query(self, context: np.ndarray, goal: np.ndarray) -> np.ndarray:
        c = self.context_weight * np.asarray(context, float).reshape(-1)
        return np.concatenate([c, np.asarray(goal, float).reshape(-1)])

    def prior_answer(self, module: int, context: np.ndarray, goal: np.ndarray) -> int:
        """The prior entry (index in the module's) that answers (context, goal), or -1 when the
        arm's own nearest is at least as near (rule 1)."""
        q = self._query(context, goal)
        j, sq_prior = self.prior[module].nearest_sq(q)
        if j < 0:
            return -1
        own = self.indexes[module]
        if len(own):
            _, sq_own = own.nearest_sq(q)  # the same formula: an equal entry is a tie
            if sq_own <= sq_prior:
                return -1
        return j

    def nearest_theta(self, module: int, context: np.ndarray, goal: np.ndarray) -> np.ndarray:
        j = self.prior_answer(module, context, goal)
        if j >= 0:
            return self.prior[module].thetas[j]
        return super().nearest_theta(module, context, goal)

    def size(self, module: int) -> int:
        """The arm's own entries and the prior's still in play."""
        return super().size(module) + int(self.prior[module].alive.sum())

    def varied(self, module: int) -> bool:
        if super().varied(module):
            return True
        p = self.prior[module]
        live = p.points[p.alive]
        return len(live) > 1 and bool(np.any(live != live[0]))

    def add(self, context: np.ndarray, outcomes: Sequence[np.ndarray | None], theta: np.ndarray):
        super().add(context, outcomes, theta)
        c = self.context_weight * np.asarray(context, dtype=float).reshape(-1)
        for k, o in enumerate(outcomes):  # rule 3
            p = self.prior[k]
            if o is None or not np.all(np.isfinite(o)) or not p.alive.any():
                continue
            point = np.concatenate([c, np.asarray(o, dtype=float).reshape(-1)])
            near = p.alive & (np.sqrt(sq_distances(p.points, point)) <= p.radius)
            self.retired_by_reach += int(near.sum())
            p.alive &= ~near

    def retire(self, source: int) -> None:
        """Take prior record ``source``'s entries out of play in every module (rule 2)."""
        for p in self.prior:
            p.alive &= p.source != source


class Prior:
    """A prior attached to a strategy (``warm_start``): the records it came from and the
    strategy's ``WarmPolicy``.

    Attributes:
        episodes: the prior records' episode numbers, (n,).
        context_ball, ball: the ball before and after each prior record, (n, 2).
        policy: the strategy's policy now.
        answered: arm episodes the prior answered so far.
    """

    def __init__(self, strategy: Strategy, records: Sequence[Experience], modules, n: int) -> None:
        self.strategy = strategy
        self.episodes = np.array([int(r.episode) for r in records], dtype=int)
        self.context_ball = np.array([np.asarray(r.context_ball, float)[:2] for r in records])
        self.ball = np.array([np.asarray(r.ball, float)[:2] for r in records])
        self.policy = WarmPolicy(strategy.policy, modules)  # type: ignore[attr-defined]
        strategy.policy = self.policy  # type: ignore[attr-defined]
        self.n = n
        self.answered = 0

    def in_play(self) -> int:
        """Prior records with an entry still in play in some module."""
        alive = [p.source[p.alive] for p in self.policy.prior]
        return len(np.unique(np.concatenate(alive))) if alive else 0

    def before_update(self, record: Experience) -> PriorAnswer | None:
        """Call with each arm record just before ``strategy.update(record)`` (a replay too):
        which prior entry answered it (None: the arm's own did, or no goal did), retired."""
        s = self.strategy
        k = record.module
        if record.kind not in DIRECTED or k < 0 or k >= len(self.policy.prior):
            return None
        if s.settings.one_outcome == "random" and not self.policy.varied(k):
            return None  # the strategy played uniform parameters (GoalExploration._plays_random)
        description = s.describe(record)
        if description is None:
            return None
        j = self.policy.prior_answer(k, description.context, record.goal)
        if j < 0:
            return None
        source = int(self.policy.prior[k].source[j])
        self.policy.retire(source)
        self.answered += 1
        return PriorAnswer(
            int(record.episode), record.kind, int(self.episodes[source]),
            self.context_ball[source].copy(), self.ball[source].copy(),
        )  # fmt: skip


def warm_start(
    strategy: Strategy, make_twin: Callable[[], Strategy], records: Sequence[Experience]
) -> Prior:
    """Attach the prior ``records`` (a run made elsewhere with the same strategy and goal
    space) to ``strategy``, which has learnt nothing yet.

    Args:
        strategy: a goal-exploration strategy, not updated yet.
        make_twin: () -> a fresh strategy built as ``strategy`` is (the same name and options):
            it reads the prior records into its goal space (their contexts, outcomes, bounds).
        records: the prior's episodes, in order.

    Raises:
        StrategyError: one line, for a strategy that cannot take a prior or records that do
            not fit its goal space or its motor primitive.
    """
    space = getattr(strategy, "space", None)
    settings = getattr(strategy, "settings", None)
    if space is None or not hasattr(strategy, "policy"):
        raise StrategyError(
            f"--warm-start: strategy {strategy.name} has no goal space to seed (goal "
            "exploration with an engineered or trained representation only)"
        )
    if getattr(settings, "schedule", "random") != "random":
        raise StrategyError(
            f"--warm-start: strategy {strategy.name} with schedule={settings.schedule}: a prior "
            "works with the random schedule only"
        )
    if not records:
        raise StrategyError("--warm-start: the prior run holds no episode")
    twin = make_twin()
    dims = len(twin.space.modules)
    sources: list[list[int]] = [[] for _ in range(dims)]
    for i, rec in enumerate(records):
        theta = np.asarray(rec.theta)
        if theta.shape != (strategy.n_params,):
            raise StrategyError(
                f"--warm-start: the prior's episode {rec.episode} has {theta.size} motor "
                f"parameters, this rig's motor primitive {strategy.n_params}: not the same arm"
            )
        outcome = twin.space.outcome(rec)
        for k, part in enumerate(twin.space.module_outcomes(outcome)):
            if part is not None and np.all(np.isfinite(part)):
                sources[k].append(i)
        twin.update(rec)  # its goal space's own checks (module, goal size) on the way
    modules = []
    for k in range(dims):
        index = twin.policy.indexes[k]
        assert len(index) == len(sources[k])
        thetas = np.array(twin.policy.thetas[k]).reshape(len(index), strategy.n_params)
        modules.append(
            _ModulePrior(
                index.points.copy(),
                thetas,
                np.array(sources[k], dtype=int),
                context_dim=twin.policy.context_dim,
                context_fraction=float(getattr(settings, "prior_context", 0.0)),
            )
        )
    prior = Prior(strategy, records, modules, len(records))
    for k in range(dims):  # rule 4: the goals' bounds start at the prior's reach
        strategy.low[k] = np.minimum(strategy.low[k], twin.low[k])  # type: ignore[attr-defined]
        strategy.high[k] = np.maximum(strategy.high[k], twin.high[k])  # type: ignore[attr-defined]
    strategy.bootstrap = max(0, strategy.bootstrap - len(records))  # type: ignore[attr-defined]
    return prior


def space_signature(strategy: Strategy) -> tuple:
    """What makes two strategies' goal spaces the same (a prior fits a strategy only if its
    run's strategy has the same): the space's kind, its modules' sizes, its context's size, and
    the representation's settings (form, tool-tip and distractor modules; the model)."""
    space = getattr(strategy, "space", None)
    if space is None:
        return (strategy.name,)
    s = getattr(strategy, "settings", None)
    return (
        type(space).__name__,
        tuple(len(m) for m in space.modules),
        getattr(space, "context_dim", None),
        *(getattr(space, key, None) for key in ("form", "hand_module", "distractor")),
        *(getattr(s, key, None) for key in ("vae", "latents", "sae")),
    )
