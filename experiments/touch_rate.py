"""How often random motor parameters move the ball on the twin, and the cells RPE reaches.

The science depends on it (docs/facts.md, the twin): goal exploration only has
something to work with once random episodes have touched the ball. Prints, per seed, the
fraction of RPE episodes that moved the ball by more than 1 cm and the ball cells reached
(30 x 30 grid over the arena's square), then the mean.

    .venv/bin/python experiments/touch_rate.py [--episodes 1000] [--seeds 0 1]
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np

from explore.runs.config import RunConfig
from explore.runs.open_run import open_run


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--episodes", type=int, default=1000)
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1])
    args = ap.parse_args()
    fractions, cells = [], []
    for seed in args.seeds:
        with tempfile.TemporaryDirectory() as tmp:
            config = RunConfig(seed=seed, episodes=args.episodes)
            with open_run(Path(tmp) / "run", config, mode="new") as run:
                ex = run.explore()
                moved = np.mean([r.ball_moved for r in run.store])
            n_cells = ex.metrics.rows[-1]["ball_cells"]
        fractions.append(moved)
        cells.append(n_cells)
        print(
            f"seed {seed}: ball moved in {moved:.1%} of {args.episodes} episodes, {n_cells} cells"
        )
    print(f"mean: moved {np.mean(fractions):.1%}, cells {np.mean(cells):.1f} after {args.episodes}")


if __name__ == "__main__":
    main()
