"""How MGE runs share their goal episodes among modules (docs/results_distractor.md F12): per
campaign folder of MGE runs, the share of the goal episodes (explore and exploit) given to each
module and how often those episodes moved the ball, means over the runs.

    .venv/bin/python experiments/module_shares.py RUNS_PARENT [RUNS_PARENT ...] [--episodes 2000]

``RUNS_PARENT``: a strategy folder of a campaign (e.g. ``distractor/mge-efr``), holding seed-S
runs. Module numbers are the goal space's order: engineered, the ball, then the distractor,
then the hand (``explore.learner.goal_spaces.EngineeredGoalSpace``).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from explore.runs.store import RunStore


def shares(run: Path, episodes: int) -> dict[int, tuple[float, float]]:
    """module -> (share of the run's goal episodes, share of those that moved the ball)."""
    recs = RunStore.read(run).records[:episodes]
    goal = [r for r in recs if r.kind in ("explore", "exploit")]
    modules = np.array([r.module for r in goal])
    moved = np.array([bool(r.ball_moved) for r in goal])
    return {int(m): (float((modules == m).mean()), float(moved[modules == m].mean()))
            for m in sorted(set(modules.tolist()))}  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("strategies", type=Path, nargs="+")
    ap.add_argument("--episodes", type=int, default=2000)
    args = ap.parse_args()
    print("| runs | module: share of goal episodes (moved the ball in them), means over runs |")
    print("|---|---|")
    for folder in args.strategies:
        per_run = [shares(run, args.episodes) for run in sorted(folder.glob("seed-*"))]
        modules = sorted({m for s in per_run for m in s})
        cells = []
        for m in modules:
            share = np.mean([s.get(m, (0.0, 0.0))[0] for s in per_run])
            moved = np.mean([s[m][1] for s in per_run if m in s])
            cells.append(f"{m}: {share:.2f} ({moved:.2f})")
        print(f"| {folder} ({len(per_run)}) | {'; '.join(cells)} |")


if __name__ == "__main__":
    main()
