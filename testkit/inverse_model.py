"""Why does goal exploration reach fewer or more ball cells than RPE? A look at its inverse
model in finished runs, engineered (rge-efr, mge-efr) or learned (rge-vae, mge-vae).

For every goal-directed episode k of a run, the nearest stored episode j < k in (context,
outcome) space to (context_k, goal_k) is found again: the 1-NN the meta-policy used (among
equally near episodes, the one its ``ties`` option picks; in the goal cycle, the one found at
the goal's first episode; no context on a scene reset before every episode), in the run's own
goal space, rebuilt from its run.json (the ball's polar features in the run's form
for the engineered strategies, plus the tool tip for mge-efr's second module; the VAE's latent
means of the outcome image, raw or z-scored as the run had them, with the previous outcome's
latent as context, for the learned ones). Prints:

- how often that neighbour had moved the ball, and how often episode k then moved it (after a
  moving neighbour and after a still one);
- how often episode k put the ball in a cell never reached before (the metric's growth);
- how well the neighbour's context matched: the distance in the arena between the ball where
  episode j started and where episode k started (the contexts, in metres);
- the distance between the ball where the neighbour left it and where episode k left it (how
  well "do what j did" reproduced j's outcome from k's context);
- a check that the neighbour found is the one used: the median |theta_k - theta_j| over the
  48 parameters, averaged over the goal episodes. Episode k played theta_j plus N(0, sigma^2)
  noise, clipped, so this is about 0.67 sigma (0.13 at the default 0.2, 0 with the noise
  off); a wrong neighbour gives about 0.6 (two uniform draws).

``figure``: per run, the arena distance of pairs of its outcomes against their distance in its
goal space, and the distribution of the context mismatch (the first of the two distances
above) over its goal episodes. ``experiments/diagnose_inverse_model.py`` prints both for run
folders.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from explore.learner.goal_spaces import LatentGoalSpace
from explore.learner.meta_policy import spread_pick
from explore.learner.strategies import STRATEGIES, StrategyError, make_strategy
from explore.report.run_data import run_scene
from explore.runs.metrics import CellCounter
from explore.runs.store import RunStore

# the strategies with an inverse model over a goal space: engineered, or a model's (registry)
ENGINEERED = tuple(name for name, entry in STRATEGIES.items() if entry.engineered)
LEARNED = tuple(name for name, entry in STRATEGIES.items() if entry.model is not None)
PAIRS = 20000  # random outcome pairs for the distance profile of the figure


class DiagnosisError(ValueError):
    """A run that cannot be diagnosed (no inverse model, no goal episode); one line."""


def figure(results: dict[str, dict[str, np.ndarray]], path: Path) -> None:
    """Two panels per run label: the arena distance of outcome pairs against their distance
    in the goal space (binned median), and the distribution of the context mismatch."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (left, right) = plt.subplots(1, 2, figsize=(11, 4.2), dpi=100)
    edges = np.linspace(0, 2.5, 26)
    for label, arr in results.items():
        x, y = arr["pair_space"], arr["pair_arena"] * 1000
        which = np.digitize(x, edges) - 1
        med = [np.median(y[which == b]) if np.sum(which == b) >= 20 else np.nan for b in range(25)]
        left.plot((edges[:-1] + edges[1:]) / 2, med, marker=".", label=label)
        gaps = np.sort(arr["start_gap"] * 1000)
        right.plot(gaps, np.arange(1, len(gaps) + 1) / len(gaps), label=label)
    left.set(xlabel="distance of two outcomes in the goal space / its median",
             ylabel="distance of their balls in the arena (mm), median",
             title="Does closeness in the goal space mean closeness in the arena?")  # fmt: skip
    right.set(xlabel="ball start of the episode vs of the neighbour it replayed (mm)",
              ylabel="fraction of goal episodes",
              title="How well the neighbour's context matched")  # fmt: skip
    for ax in (left, right):
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def run_strategy(run: Path, vae_dir: Path | None = None) -> Any:
    """The run's strategy made again from its ``run.json`` (``vae_dir``: another model folder
    for a learned one); a DiagnosisError for a strategy without an inverse model."""
    config = RunStore.read_meta(run)["config"]
    strategy = config["strategy"]
    name, options = strategy["name"], dict(strategy.get("options", {}))
    if name not in ENGINEERED + LEARNED:
        raise DiagnosisError(f"{run}: strategy {name!r} has no inverse model to diagnose")
    if vae_dir is not None and name in LEARNED:
        options[STRATEGIES[name].model.option] = str(vae_dir)  # type: ignore[union-attr]
    try:
        return make_strategy(name, scene=run_scene(config), **options)
    except StrategyError as exc:
        raise DiagnosisError(f"{run}: {exc}") from None


def goal_space_vectors(
    run: Path, recs: list, vae_dir: Path | None, made: Any = None
) -> tuple[np.ndarray, np.ndarray, list[np.ndarray]]:
    """The vectors the run's meta-policy stored, in the run's own goal space (its strategy
    rebuilt from ``run.json``, as ``explore.learner.goal_outcomes.goal_outcome_of`` does):
    contexts (n, c) (times the run's ``context_weight``, as its meta-policy stored them; c = 0
    on a scene that resets before every episode, whose meta-policy stores none),
    outcomes (n, d) (NaN where not seen), modules (coordinate index arrays of the outcome).
    ``made``: the run's strategy when the caller made it already (``run_strategy``)."""
    made = run_strategy(run, vae_dir) if made is None else made
    space = made.space
    weight = made.settings.context_weight
    if isinstance(space, LatentGoalSpace):
        out = space.outcomes(np.stack([r.image for r in recs]))
        ctx = np.vstack([np.zeros((1, space.dim)), out[:-1]])  # previous outcome; zeros first
    else:
        ctx = np.array([space.context(r) for r in recs])
        unseen = np.full(space.dim, np.nan)
        out = np.array([o if (o := space.outcome(r)) is not None else unseen for r in recs])
    if made.scene.resets:  # every episode starts from the same scene: no context stored
        ctx = np.zeros((len(recs), 0))
    return weight * ctx, out, list(space.modules)


def diagnose(
    run: Path, vae_dir: Path | None = None, arrays: dict[str, np.ndarray] | None = None
) -> dict[str, float]:
    """Statistics of one run's goal-directed episodes (fractions in [0, 1], distances in m).

    ``arrays``, when given, receives the figure's data: ``start_gap`` (g,) m, per goal
    episode; ``pair_space`` and ``pair_arena`` (p,): goal-space distance (over the median
    one) and arena distance (m) of random pairs of outcomes.
    """
    recs = RunStore.read(run).records
    made = run_strategy(run, vae_dir)
    ctx, out, modules = goal_space_vectors(run, recs, vae_dir, made)
    settings = made.settings
    # the goal cycle (schedule "cycle"): a goal's noisy episodes all vary the neighbour found
    # at its first episode; its exploit, the last, looks again
    cycle = settings.schedule == "cycle"
    cycle_length = settings.n_explore + 1
    goal_episodes, cycle_j = 0, -1
    moved = np.array([r.ball_moved for r in recs])
    balls = np.array([np.asarray(r.ball, dtype=float)[:2] for r in recs])
    counter = CellCounter(run_scene(RunStore.read_meta(run)["config"]).ball_half_width)
    new_cell = np.zeros(len(recs), dtype=bool)
    for k, b in enumerate(balls):
        before = counter.count
        new_cell[k] = counter.add(b) > before
    starts = np.array([np.asarray(r.context_ball, dtype=float)[:2] for r in recs])
    nn_moved, k_moved, k_new, ball_gap, start_gap, theta_gap = [], [], [], [], [], []
    for k, r in enumerate(recs):
        if r.kind not in ("explore", "exploit") or k == 0:
            continue
        m = modules[r.module]
        if r.goal.shape != (len(m),):
            raise DiagnosisError(f"{run}: goal of shape {r.goal.shape}, module of {len(m)}")
        position = goal_episodes % cycle_length if cycle else 0
        goal_episodes += 1
        if 0 < position < cycle_length - 1:
            j = cycle_j
        else:
            points = np.hstack([ctx[:k], out[:k, m]])
            seen = np.flatnonzero(np.all(np.isfinite(points), axis=1))
            query = np.concatenate([ctx[k], r.goal]).astype(float)
            dist = np.linalg.norm(points[seen] - query, axis=1)
            tied = seen[dist == dist.min()]  # the run's own choice among equally near ones
            j = spread_pick(query, tied) if settings.ties == "spread" else int(tied[0])
            cycle_j = j
        nn_moved.append(moved[j])
        k_moved.append(moved[k])
        k_new.append(new_cell[k])
        ball_gap.append(float(np.linalg.norm(balls[k] - balls[j])))
        start_gap.append(float(np.linalg.norm(starts[k] - starts[j])))
        theta_gap.append(float(np.median(np.abs(r.theta - recs[j].theta))))
    a, b = np.array(nn_moved, dtype=bool), np.array(k_moved, dtype=bool)
    if len(a) == 0:
        raise DiagnosisError(f"{run}: no goal-directed episode")
    if arrays is not None:
        arrays["start_gap"] = np.array(start_gap)
        ok = np.flatnonzero(np.all(np.isfinite(out), axis=1) & np.all(np.isfinite(balls), axis=1))
        i, j = np.random.default_rng(0).choice(ok, (2, PAIRS))
        space = np.linalg.norm(out[i] - out[j], axis=1)
        arrays["pair_space"] = space / np.median(space)
        arrays["pair_arena"] = np.linalg.norm(balls[i] - balls[j], axis=1)
    return {
        "goal_episodes": float(len(a)),
        "neighbour_moved": float(a.mean()),
        "moved": float(b.mean()),
        "moved_after_moving_neighbour": float(b[a].mean()) if a.any() else float("nan"),
        "moved_after_still_neighbour": float(b[~a].mean()) if (~a).any() else float("nan"),
        "new_cell": float(np.mean(k_new)),
        "ball_gap_m": float(np.nanmedian(ball_gap)),
        "start_gap_m": float(np.nanmedian(start_gap)),
        "theta_gap": float(np.mean(theta_gap)),
        "moved_all_episodes": float(moved.mean()),
    }
