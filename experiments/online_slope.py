"""RGE-Online's slope after its switch against RPE's, per seed, from a campaign folder.

    .venv/bin/python experiments/online_slope.py runs/paper/stay [--switch 2000] [--end 5000] \
        [--figure docs/img/results_final_online.png]

The slope is the ball cells gained per 1000 episodes from the switch (rge-online's bootstrap
length, 2000 by default: its first episodes are RPE's with the same seed) to ``--end``, read
from each run's ``metrics.csv`` (``ball_cells`` after each episode, the project's metric).
Prints one line per strategy (per-seed slopes, mean ± sd) and Welch's t-test of rge-online's
slopes against RPE's (one-sided: rge-online's larger).
"""

from __future__ import annotations

import argparse
import csv
from pathlib import Path

import numpy as np
from scipy import stats
from script_helpers import save_figure  # experiments/script_helpers.py, beside this script

from explore.runs.layout import METRICS_FILE


def cells_per_run(strategy_dir: Path) -> dict[str, list[int]]:
    """seed folder name -> ball cells after each episode (``metrics.csv``), in episode order."""
    out = {}
    for run in sorted(strategy_dir.glob("seed-*")):
        with (run / METRICS_FILE).open() as f:
            out[run.name] = [int(row["ball_cells"]) for row in csv.DictReader(f)]
    return out


def slopes(runs: dict[str, list[int]], switch: int, end: int) -> dict[str, float]:
    """seed -> cells gained per 1000 episodes over [switch, end), for the runs that reach end."""
    return {
        seed: (cells[end - 1] - cells[switch - 1]) * 1000.0 / (end - switch)
        for seed, cells in runs.items()
        if len(cells) >= end
    }


def curves(runs: dict[str, list[int]], end: int) -> np.ndarray:
    """Ball cells after each episode, shape (runs, end), of the runs that reach ``end``."""
    return np.array([cells[:end] for cells in runs.values() if len(cells) >= end], dtype=float)


def figure(runs: dict[str, dict[str, list[int]]], switch: int, end: int, path: Path) -> None:
    """Mean ± sd of the ball cells against episodes, RPE and RGE-Online, the switch marked."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.0))
    x = np.arange(1, end + 1)
    for name, colour in (("rpe", "tab:gray"), ("rge-online", "tab:purple")):
        c = curves(runs[name], end)
        m, sd = c.mean(axis=0), c.std(axis=0, ddof=1)
        ax.plot(x, m, color=colour, label=f"{name} ({len(c)} seeds)")
        ax.fill_between(x, m - sd, m + sd, color=colour, alpha=0.2)
    ax.axvline(switch, color="k", lw=0.8, ls="--", label="switch (VAE trained)")
    ax.set_xlabel("episodes")
    ax.set_ylabel("ball cells reached")
    ax.legend(loc="upper left")
    fig.tight_layout()
    save_figure(fig, path)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("campaign", type=Path)
    ap.add_argument("--switch", type=int, default=2000, help="rge-online's bootstrap length")
    ap.add_argument("--end", type=int, default=5000, help="the last episode counted")
    ap.add_argument("--figure", type=Path, help="write the curves' figure there (PNG)")
    args = ap.parse_args()
    found, runs = {}, {}
    for name in ("rpe", "rge-online"):
        runs[name] = cells_per_run(args.campaign / name)
        s = slopes(runs[name], args.switch, args.end)
        if not s:
            raise SystemExit(f"{args.campaign / name}: no run reaches {args.end} episodes")
        v = np.array(list(s.values()))
        found[name] = v
        per = " ".join(f"{x:.1f}" for x in v)
        print(f"{name:11s} {len(v)} seeds: {v.mean():.1f} ± {v.std(ddof=1):.1f} cells/1000 ({per})")
    t = stats.ttest_ind(found["rge-online"], found["rpe"], equal_var=False, alternative="greater")
    ratio = found["rge-online"].mean() / found["rpe"].mean()
    print(f"rge-online / rpe: {ratio:.2f}x, Welch one-sided p = {t.pvalue:.2g}")
    if args.figure:
        figure(runs, args.switch, args.end, args.figure)


if __name__ == "__main__":
    main()
