"""Where and how long twin runs stall (issue 31, step 1): per run, the episodes that lie in a
stall (a window of ``--window`` episodes after the bootstrap in which the ball moved at most
``--moves`` times), where the ball sat then (median distance from the arena's centre, mm, and
angle, degrees), and how many of the stalled episodes of each kind (goal "explore" episodes,
"random" parameters) moved it.

    .venv/bin/python experiments/twin_stalls.py RUN [RUN ...] [--window 100] [--moves 2]

Reads the runs' histories only; prints one Markdown row per run (docs/results_stalls.md, F7).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from explore.campaigns.stats import final_cells
from explore.learner.strategies.goal_exploration import BOOTSTRAP  # the default bootstrap
from explore.runs.store import RunStore


def stalled_episodes(moved: np.ndarray, window: int, moves: int) -> np.ndarray:
    """Mask (n,) of the episodes inside a window of ``window`` episodes, starting after the
    bootstrap, in which ``moved`` (n,) holds at most ``moves`` true values."""
    n = len(moved)
    mask = np.zeros(n, dtype=bool)
    for i in range(BOOTSTRAP, n - window + 1):
        if moved[i : i + window].sum() <= moves:
            mask[i : i + window] = True
    return mask


def describe(run: Path, window: int, moves: int) -> str:
    records = RunStore.read(run).records
    moved = np.array([bool(r.ball_moved) for r in records])
    cells = final_cells(run)[1]
    idx = np.flatnonzero(stalled_episodes(moved, window, moves))
    if len(idx) == 0:
        return f"| {run} | {cells} | none | | | |"
    xy = np.array([records[i].context_ball[:2] for i in idx])
    r_mm = 1000.0 * np.hypot(xy[:, 0], xy[:, 1])
    angle = np.degrees(np.arctan2(xy[:, 1], xy[:, 0]))
    counts = {}
    for i in idx:
        n, m = counts.get(records[i].kind, (0, 0))
        counts[records[i].kind] = (n + 1, m + int(moved[i]))
    goal = counts.get("explore", (0, 0))
    rand = counts.get("random", (0, 0))
    return (
        f"| {run} | {cells} | {len(idx)} ({idx[0]}-{idx[-1]}) | {np.median(r_mm):.0f} mm, "
        f"{np.median(angle):.0f} deg | {goal[1]} of {goal[0]} | {rand[1]} of {rand[0]} |"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", type=Path, nargs="+")
    ap.add_argument("--window", type=int, default=100)
    ap.add_argument("--moves", type=int, default=2)
    args = ap.parse_args()
    print("| run | ball cells at the end | episodes in stalls | where the ball sat (median) | "
          "goal episodes that moved it there | random episodes that moved it there |")  # fmt: skip
    print("|---|---|---|---|---|---|")
    for run in args.runs:
        print(describe(run, args.window, args.moves))


if __name__ == "__main__":
    main()
