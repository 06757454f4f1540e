"""Figures of the distractor experiment: MGE's interest per module over the episodes, and the
final positions of the ball and the distractor per strategy.

Interest is rebuilt by replaying each MGE run's history through its own strategy (made again
from its run.json, as a resumed run rebuilds it: the state is a function of the records), and
read after every episode. Each module is named by what it follows: the engineered modules by
construction (ball, distractor, hand); a spatial autoencoder's by the object its feature's
position predicts best (held-out free: the linear R^2 over the run's own outcomes, a
diagnostic of the figure only, never seen by the strategy).

    .venv/bin/python experiments/distractor_figures.py CAMPAIGN [--out docs/img] \
        [--prefix results_distractor]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from script_helpers import (
    linear_r2,
    save_figure,
)  # experiments/script_helpers.py, beside this script

from explore.learner.goal_spaces import EngineeredGoalSpace
from explore.runs.config import RunConfig
from explore.runs.layout import RUN_FILE
from explore.runs.open_run import strategy_for
from explore.runs.store import RunStore


def interests_over_time(run: Path) -> tuple[np.ndarray, list[str]]:
    """(interest after each episode (n, modules), module names) of an MGE run."""
    store = RunStore.read(run)  # a reader: cuts nothing
    strategy = strategy_for(RunConfig.of_run(store.config, run / RUN_FILE))
    rows = []
    for rec in store:
        strategy.update(rec)
        space = strategy.space
        rows.append(strategy.interest.interests() if space is not None else [])
    space = strategy.space
    names = module_names(space, store.records)
    store.close()
    return np.array(rows), names


def module_names(space: object, records: list) -> list[str]:
    if isinstance(space, EngineeredGoalSpace):
        names = ["ball"] + (["distractor"] if space.distractor else [])
        return names + (["hand"] if space.hand_module else [])
    outcomes = space.outcomes(np.stack([r.image for r in records]))  # type: ignore[attr-defined]
    ball = np.stack([r.ball for r in records])
    dis = np.stack([r.distractor for r in records])
    names = []
    for k, idx in enumerate(space.modules):  # type: ignore[attr-defined]
        fits = {}
        for label, y in (("ball", ball), ("distractor", dis)):
            ok = np.all(np.isfinite(y), axis=1)
            fits[label] = linear_r2(outcomes[ok][:, idx], y[ok], pooled=True)
        best = max(fits, key=fits.get)  # type: ignore[arg-type]
        names.append(f"feature {k}: {best} (R² {fits[best]:.2f})")
    return names


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("campaign", type=Path)
    ap.add_argument("--out", type=Path, default=Path("docs/img"))
    ap.add_argument("--prefix", default="results_distractor")
    args = ap.parse_args()
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    strategies = sorted(p.name for p in args.campaign.iterdir() if (p / "seed-100").exists()
                        or any(p.glob("seed-*")))  # fmt: skip
    mge = [s for s in strategies if s.startswith("mge-")]
    fig, axes = plt.subplots(1, len(mge), figsize=(6 * len(mge), 4), squeeze=False)
    for ax, name in zip(axes[0], mge, strict=True):
        curves: dict[str, list[np.ndarray]] = {}
        for run in sorted((args.campaign / name).glob("seed-*")):
            interest, names = interests_over_time(run)
            for k, label in enumerate(names):
                key = label.split(" (R²")[0].split(": ")[-1] if name != "mge-efr" else label
                curves.setdefault(key, []).append(interest[:, k])
        for label, runs in curves.items():
            n = min(len(r) for r in runs)
            mean = np.mean([r[:n] for r in runs], axis=0)
            ax.plot(np.arange(1, n + 1), mean, label=f"{label} ({len(runs)} module-runs)")
        ax.set_title(f"{name}: interest per module (mean over runs)")
        ax.set_xlabel("episode")
        ax.set_ylabel("interest |mean learning progress|")
        ax.legend(fontsize=8)
    fig.tight_layout()
    args.out.mkdir(parents=True, exist_ok=True)
    interest_png = args.out / f"{args.prefix}_interest.png"
    save_figure(fig, interest_png)
    fig, axes = plt.subplots(1, len(strategies), figsize=(3.2 * len(strategies), 3.4),
                             squeeze=False)  # fmt: skip
    for ax, name in zip(axes[0], strategies, strict=True):
        run = sorted((args.campaign / name).glob("seed-*"))[0]
        store = RunStore.read(run)
        ball = np.stack([r.ball for r in store])
        dis = np.stack([r.distractor for r in store])
        store.close()
        ax.scatter(dis[:, 0], dis[:, 1], s=2, c="tab:red", alpha=0.3, label="distractor")
        ax.scatter(ball[:, 0], ball[:, 1], s=2, c="olive", alpha=0.5, label="ball")
        ax.set_title(f"{name}, {run.name}", fontsize=9)
        ax.set_aspect("equal")
        ax.set_xlim(-0.2, 0.2)
        ax.set_ylim(-0.2, 0.2)
    axes[0][0].legend(fontsize=7, loc="lower left")
    fig.tight_layout()
    scatter_png = args.out / f"{args.prefix}_scatter.png"
    save_figure(fig, scatter_png)


if __name__ == "__main__":
    main()
