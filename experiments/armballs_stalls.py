"""Stalled MGE-EFR runs on Arm-2-Balls: per-run figures of one or more campaign folders, side by
side (docs/results_armballs_stalls.md, "Stalls: cause and fix").

For every run of ``CAMPAIGN/STRATEGY/seed-*`` (default strategy ``mge-efr``):
- the exploration ratio at 1000, 3000, 5000 and 9666 iterations (the published checkpoints),
  and whether it lies below the lowest of the 30 published MGE-EFR runs there
  (docs/armballs_published_runs.csv);
- how many of the 100 bootstrap episodes moved the ball, and the first episode that did;
- the share of the goal-directed episodes 100-999 whose goal was in the ball's module (module 0:
  ``EngineeredGoalSpace`` puts the ball first) and the largest share any one module took;
- the share of the ball module's episodes played while that module had only ever seen one
  outcome (the ball at its start), and the random share of the episodes;
- with ``--interest``, the share of episodes 100-999 after which the ball module's interest
  exceeded the distractor's (the histories replayed through the runs' own strategies).

    .venv/bin/python experiments/armballs_stalls.py runs/stalls/before runs/stalls/after \\
        [--strategy mge-efr] [--figure docs/img/armballs_stalls.png] [--interest]

Prints one Markdown table per campaign (one row a run), then the summary table (mean +- sd over
runs, ddof 1; the minimum; runs below the published minimum; Welch's p of each campaign against
the first one), and with ``--figure`` draws every run's exploration curve per campaign over the
published runs' range.
"""

from __future__ import annotations

import argparse
import csv
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from script_helpers import save_figure  # experiments/script_helpers.py, beside this script

from explore.runs.layout import METRICS_FILE, RUN_FILE
from plumbing.cli_errors import error

ROOT = Path(__file__).resolve().parents[1]
PUBLISHED_RUNS = ROOT / "docs" / "armballs_published_runs.csv"
PUBLISHED = ROOT / "docs" / "armballs_published.csv"
AT = (1000, 3000, 5000, 9666)  # the published table's checkpoints (iterations)
BOOTSTRAP = 100  # the corl2018 preset's engineered bootstrap (column n_bootstrap)
EARLY = (100, 1000)  # the goal-directed episodes the stalled run was read on
BALL_MODULE = 0


@dataclass
class RunFigures:
    """One run's figures (fractions in [0, 1]; episodes counted from 0)."""

    seed: int
    ratios: np.ndarray  # exploration ratio at AT, shape (len(AT),)
    curve: np.ndarray  # exploration ratio at the 30 published checkpoints, shape (30,)
    bootstrap_moves: int  # bootstrap episodes that moved the ball
    first_move: int  # first episode that moved the ball (-1: none)
    ball_share_early: float  # share of goal episodes 100-999 in the ball's module
    top_share_early: float  # largest share of one module there
    random_share: float  # share of all episodes with random parameters
    blind_ball_share: float  # ball-module episodes played before it saw a second outcome
    ball_lead_early: float = float("nan")  # share of episodes 100-999 after which the ball's
    # interest exceeded the distractor's (NaN: not computed); ``--interest``


def published_runs(algorithm: str = "MGE-EFR") -> dict[int, np.ndarray]:
    """iterations -> the published runs' exploration ratios (docs/armballs_published_runs.csv)."""
    out: dict[int, list[float]] = {}
    with open(PUBLISHED_RUNS, newline="") as f:
        for row in csv.DictReader(f):
            if row["algorithm"] == algorithm:
                out.setdefault(int(row["iterations"]), []).append(float(row["exploration_30"]))
    # the file holds cells / 900 rounded to 6 decimals (79 cells: 0.087778, above 79 / 900):
    # back to whole cells, so that a run with as many cells as the published minimum is not below
    from explore.runs.metrics import N_BINS

    cells = N_BINS**2
    return {k: np.round(np.array(v) * cells) / cells for k, v in out.items()}


def published_band(algorithm: str = "MGE-EFR") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Checkpoints, mean and sd of the published runs (docs/armballs_published.csv)."""
    rows = []
    with open(PUBLISHED, newline="") as f:
        for row in csv.DictReader(f):
            if row["algorithm"] == algorithm:
                rows.append((int(row["iterations"]), float(row["mean"]), float(row["sd"])))
    rows.sort()
    a = np.array(rows)
    return a[:, 0], a[:, 1], a[:, 2]


def run_figures(run: Path) -> RunFigures:
    """The figures of one run folder (reads its metrics.csv and history)."""
    from explore.runs.metrics import checkpoints, exploration_ratio, read_metrics
    from explore.runs.store import iter_history

    cells = read_metrics(run / METRICS_FILE)["ball_cells"]
    curve = exploration_ratio(cells, checkpoints())
    ratios = exploration_ratio(cells, np.array(AT))
    episode, module, moved, random = [], [], [], []
    blind, seen = 0, 0
    outcomes: set[tuple[float, float]] = set()
    for r in iter_history(run):
        episode.append(r.episode)
        module.append(r.module)
        moved.append(bool(r.ball_moved))
        random.append(r.kind == "random")
        if r.module == BALL_MODULE:
            seen += 1
            blind += len(outcomes) <= 1
        outcomes.add((float(r.ball[0]), float(r.ball[1])))
    e, m, mv = np.array(episode), np.array(module), np.array(moved)
    early = m[(e >= EARLY[0]) & (e < EARLY[1]) & (m >= 0)]
    shares = np.bincount(early, minlength=2) / max(len(early), 1)
    first = np.flatnonzero(mv)
    return RunFigures(
        seed=int(run.name.split("-")[1]),
        ratios=ratios,
        curve=curve,
        bootstrap_moves=int(mv[e < BOOTSTRAP].sum()),
        first_move=int(e[first[0]]) if len(first) else -1,
        ball_share_early=float(shares[BALL_MODULE]),
        top_share_early=float(shares.max()),
        random_share=float(np.mean(random)),
        blind_ball_share=blind / max(seen, 1),
    )


def ball_lead_early(run: Path) -> float:
    """The share of episodes 100-999 after which the ball module's interest (module 0) exceeded
    the distractor's (module 1), rebuilt by replaying the history through the run's own
    strategy."""
    from explore.runs.config import RunConfig
    from explore.runs.open_run import strategy_for
    from explore.runs.store import RunStore

    store = RunStore.read(run)  # a reader: cuts nothing
    strategy = strategy_for(RunConfig.of_run(store.config, run / RUN_FILE))
    lead = []
    try:
        for rec in store:
            strategy.update(rec)
            if rec.episode >= EARLY[1]:
                break
            if rec.episode >= EARLY[0]:
                interest = strategy.interest.interests()
                lead.append(interest[BALL_MODULE] > interest[1])
    finally:
        store.close()
    return float(np.mean(lead)) if lead else float("nan")


def campaign_figures(campaign: Path, strategy: str, interest: bool = False) -> list[RunFigures]:
    runs = sorted((campaign / strategy).glob("seed-*"), key=lambda p: int(p.name.split("-")[1]))
    out = [run_figures(r) for r in runs if (r / METRICS_FILE).exists()]
    if interest:
        for fig, run in zip(out, [r for r in runs if (r / METRICS_FILE).exists()], strict=True):
            fig.ball_lead_early = ball_lead_early(run)
    return out


def runs_table(runs: list[RunFigures], floor: dict[int, float]) -> str:
    """One row a run; ratios below the published minimum in bold."""
    head = ("| seed | bootstrap moves | first move | ball share 100-999 | top module share "
            "100-999 | ball's interest above the distractor's, 100-999 | "
            + " | ".join(f"at {n}" for n in AT) + " |")  # fmt: skip
    lines = [head, "|" + "---|" * (6 + len(AT))]
    for r in runs:
        lead = "-" if np.isnan(r.ball_lead_early) else f"{r.ball_lead_early:.2f}"
        cells = [
            f"**{v:.3f}**" if v < floor[n] else f"{v:.3f}"
            for n, v in zip(AT, r.ratios, strict=True)
        ]
        lines.append(
            f"| {r.seed} | {r.bootstrap_moves} | {r.first_move} | {r.ball_share_early:.2f} | "
            f"{r.top_share_early:.2f} | {lead} | " + " | ".join(cells) + " |"
        )
    return "\n".join(lines)


def summary_table(named: dict[str, list[RunFigures]], pub: dict[int, np.ndarray]) -> str:
    from scipy import stats

    lines = [
        "| campaign | runs | " + " | ".join(f"{n}: mean ± sd | min | below published min"
                                            for n in AT) + " | distractor share 100-999 > 0.9 |",
        "|" + "---|" * (2 + 3 * len(AT) + 1),
    ]  # fmt: skip
    pub_line = ["| published MGE-EFR | " + str(len(pub[AT[0]]))]
    for n in AT:
        p = pub[n]
        pub_line.append(f"{p.mean():.3f} ± {np.std(p, ddof=1):.3f} | {p.min():.3f} | -")
    lines.append(" | ".join(pub_line) + " | - |")
    first = next(iter(named.values()))
    for name, runs in named.items():
        r = np.array([x.ratios for x in runs])
        ref = np.array([x.ratios for x in first])
        row = [f"| {name} | {len(runs)}"]
        for j, n in enumerate(AT):
            p = ""
            if runs is not first:
                p = f" (p {stats.ttest_ind(r[:, j], ref[:, j], equal_var=False).pvalue:.2g})"
            row.append(f"{r[:, j].mean():.3f} ± {np.std(r[:, j], ddof=1):.3f}{p} | "
                       f"{r[:, j].min():.3f} | {int(np.sum(r[:, j] < pub[n].min()))}")  # fmt: skip
        stalled = sum(1 - x.ball_share_early > 0.9 for x in runs)
        lines.append(" | ".join(row) + f" | {stalled} |")
    return "\n".join(lines)


def figure(named: dict[str, list[RunFigures]], out: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from explore.runs.metrics import checkpoints

    n, mean, sd = published_band()
    x = checkpoints()
    fig, axes = plt.subplots(1, len(named), figsize=(5.2 * len(named), 4.0), squeeze=False)
    for ax, (name, runs) in zip(axes[0], named.items(), strict=True):
        ax.fill_between(n, mean - sd, mean + sd, color="0.85", label="published mean ± sd")
        ax.plot(n, mean, "k--", lw=1, label="published mean")
        for j, at in enumerate(AT):
            lo = published_runs()[at].min()
            ax.plot([at], [lo], "kv", ms=5, label="published minimum" if j == 0 else None)
        for r in runs:
            low = np.any(r.ratios < np.array([published_runs()[a].min() for a in AT]))
            ax.plot(x, r.curve, color="tab:red" if low else "tab:blue", lw=1.6 if low else 0.8,
                    alpha=0.9 if low else 0.5)  # fmt: skip
        ax.set_title(f"{name}: MGE-EFR, {len(runs)} runs (red: below the published min)",
                     fontsize=9)  # fmt: skip
        ax.set_xlabel("iterations")
        ax.set_ylim(0, 0.9)
        ax.grid(alpha=0.3)
    axes[0][0].set_ylabel("exploration ratio (30 x 30 cells)")
    axes[0][0].legend(fontsize=7, loc="lower right")
    fig.tight_layout()
    save_figure(fig, out)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("campaigns", nargs="+", type=Path, help="campaign folders, first = reference")
    ap.add_argument("--strategy", default="mge-efr")
    ap.add_argument("--figure", type=Path, default=None, help="PNG of every run's curve")
    ap.add_argument(
        "--interest", action="store_true", help="replay: how long the ball's interest led early"
    )
    args = ap.parse_args(argv)
    pub = published_runs()
    floor = {n: float(pub[n].min()) for n in AT}
    named = {}
    for c in args.campaigns:
        if not (c / args.strategy).is_dir():
            return error(
                f"{c} has no {args.strategy}/ folder: give a campaign folder of `ergo experiment`"
            )
        runs = campaign_figures(c, args.strategy, args.interest)
        named[c.name] = runs
        print(f"## {c}\n\n{runs_table(runs, floor)}\n")
        print(f"random episodes: {np.mean([r.random_share for r in runs]):.4f} of all; "
              "ball-module episodes before its second distinct outcome: "
              f"{np.mean([r.blind_ball_share for r in runs]):.4f}\n")  # fmt: skip
    print(summary_table(named, pub))
    if args.figure:
        print()
        figure(named, args.figure)
    return 0


if __name__ == "__main__":
    sys.exit(main())
