"""Where a prior costs the arm (docs/warm_start.md, "Where the prior costs"): of the episodes a
prior answered in warmed runs, the share that moved the ball, by how far the twin episode's ball
started from the arm's, against the arm's own goal episodes in the same runs.

For each warmed run (its ``reality_gap.csv``, read by ``explore.report.reality_gap``: the
prior episode's ball before and after, the arm's), the distance between the two starting balls,
in mm and, for the engineered goal space, as a fraction of the diagonal of the prior's contexts
in the space's coordinates (what the option ``prior_context`` of rule 5 measures,
``explore/learner/prior.py``); the episode moved
the ball when its ``metrics.csv`` says so (a move over 1 cm). The arm's own goal episodes are
the explore and exploit episodes the prior did not answer.

    .venv/bin/python experiments/prior_context.py RUN [RUN ...]   # warmed runs (rge-efr)
"""

from __future__ import annotations

import argparse
import itertools
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from explore.learner.strategies import make_strategy
from explore.report.reality_gap import read_gap
from explore.rigs.rig import RigConfig, rig_scene
from explore.runs.config import RunConfig
from explore.runs.layout import PRIOR_KEY, RUN_FILE
from explore.runs.metrics import read_metrics
from explore.runs.store import RunStore, read_history

MM_BINS = (0, 20, 40, 80, 160, 1000)
FRACTION_BINS = (0, 0.05, 0.1, 0.15, 0.2, 0.3, 10)


def one_run(run: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per answered episode: (distance of the starting balls, mm; as a fraction of the prior's
    context diagonal, NaN for a learned space; moved), and per own goal episode: moved."""
    meta = RunStore.read_meta(run)
    config = RunConfig.of_run(meta["config"], run / RUN_FILE)
    metrics = read_metrics(run / "metrics.csv")
    moved = np.asarray(metrics["ball_moved"], dtype=int).astype(bool)
    kinds = np.asarray(metrics["kind"])
    gap = read_gap(run)
    keep = gap.episode < len(moved)
    answered = gap.episode[keep]
    prior_start, arm_start = gap.prior_start[keep], gap.arm_start[keep]
    mm = 1e3 * np.sqrt(((prior_start - arm_start) ** 2).sum(axis=1))
    fraction = np.full(len(answered), np.nan)
    scene = rig_scene(RigConfig(config.rig.name, config.rig.rig_id, dict(config.rig.options)))
    strategy = make_strategy(config.strategy.name, 1, scene=scene, **config.strategy.options)
    space = strategy.space
    if hasattr(space, "context_of"):  # the engineered space: contexts from the balls
        prior = read_history(Path(meta[PRIOR_KEY]["path"])).records
        contexts = np.array([space.context_of(r.context_ball, None) for r in prior])
        diagonal = np.sqrt(((contexts.max(axis=0) - contexts.min(axis=0)) ** 2).sum())
        a = np.array([space.context_of(b, None) for b in prior_start])
        b = np.array([space.context_of(b, None) for b in arm_start])
        fraction = np.sqrt(((a - b) ** 2).sum(axis=1)) / diagonal
    own = np.isin(kinds, ("explore", "exploit"))
    own[answered] = False
    return mm, fraction, moved[answered], moved[own]


def table(values: np.ndarray, moved: np.ndarray, bins: tuple[float, ...], unit: str) -> None:
    print(f"| starting balls apart ({unit}) | answered | moved the ball |")
    print("|---|---|---|")
    for lo, hi in itertools.pairwise(bins):
        m = (values >= lo) & (values < hi)
        if m.any():
            print(f"| {lo:g}-{hi:g} | {int(m.sum())} | {moved[m].mean():.0%} |")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("runs", nargs="+", type=Path, help="warmed run folders")
    args = p.parse_args()
    parts = [one_run(run) for run in args.runs]
    mm, fraction, moved, own = (np.concatenate(x) for x in zip(*parts, strict=True))
    for run, (_, _, m, o) in zip(args.runs, parts, strict=True):
        print(f"{run}: the prior answered {len(m)} (moved {m.mean():.0%}); own goal episodes "
              f"{len(o)} (moved {o.mean():.0%})")  # fmt: skip
    own_shares = [o.mean() for _, _, _, o in parts]
    print(f"own goal episodes moved the ball: {own.mean():.0%} over all, "
          f"{min(own_shares):.0%}-{max(own_shares):.0%} per run")  # fmt: skip
    table(mm, moved, MM_BINS, "mm")
    if np.isfinite(fraction).any():
        table(fraction, moved, FRACTION_BINS, "fraction of the prior's context diagonal")


if __name__ == "__main__":
    main()
