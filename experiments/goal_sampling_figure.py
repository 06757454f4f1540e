"""Goals and outcomes over the arena, side by side for several runs (e.g. the same seed with
``goal_sampling`` uniform and another sampler): one panel per run, each the arena panel of
the run report's ``arena.png`` (explore/report/arena.py), over its first ``--episodes``.

    .venv/bin/python experiments/goal_sampling_figure.py RUN [RUN ...] --out PNG
        [--episodes 1500]
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

import numpy as np

from explore.report.arena import confinement, draw_arena
from explore.report.run_data import RunData, load_run


def first(run: RunData, n: int) -> RunData:
    """The run cut to its first ``n`` episodes."""
    cut = {
        f.name: getattr(run, f.name)[:n]
        for f in dataclasses.fields(run)
        if isinstance(getattr(run, f.name), np.ndarray)
    }
    return dataclasses.replace(run, **cut)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", type=Path, nargs="+")
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--episodes", type=int, default=1500)
    args = ap.parse_args()
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = len(args.runs)
    fig, axes = plt.subplots(1, n, figsize=(4.8 * n, 5.2), dpi=100, squeeze=False)
    for ax, path in zip(axes[0], args.runs, strict=True):
        run = first(load_run(path), args.episodes)
        c = confinement(run)
        draw_arena(ax, run, c)
        sampling = run.config["strategy"].get("options", {}).get("goal_sampling", "uniform")
        title = ax.get_title()
        ax.set_title(
            f"{run.strategy}, goal_sampling {sampling}, seed {run.seed}: "
            f"{int(run.ball_cells[-1])} cells\n{title}",
            fontsize=8,
        )
    fig.tight_layout()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.out)
    print(f"figure: {args.out}")


if __name__ == "__main__":
    main()
