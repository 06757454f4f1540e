"""Ball cells of a campaign's runs at given episodes, per strategy, with Welch's t-test against
reference strategies (docs/results.md F9, docs/results_vae.md F11): one Markdown row per strategy.

    .venv/bin/python experiments/campaign_table.py CAMPAIGN [CAMPAIGN ...] --at 1500,5000 \
        --against rpe,rge-efr [--seeds 700-707]

Reads each run's ``metrics.csv`` (the ball cells after each episode); a run that has not
reached an episode shows "-" there and is left out of that column's statistics. The last
column: the share of the episodes (up to the last ``--at``) that moved the ball, over the
runs. Strategies with the same name in two campaigns are told apart by the campaign folder's
name.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from explore.campaigns.stats import welch_vs_baseline
from explore.runs.layout import METRICS_FILE
from explore.runs.metrics import read_metrics
from vision.cli import parse_seeds


def cells_at(run: Path, episodes: list[int]) -> tuple[list[int | None], float]:
    """The ball cells after each of ``episodes`` (1-based counts) of one run, None where the
    run is shorter, and the share of its episodes up to the last of them that moved the
    ball."""
    m = read_metrics(run / METRICS_FILE)
    cells = m["ball_cells"].astype(int)
    moved = float(m["ball_moved"][: episodes[-1]].mean())
    return [int(cells[n - 1]) if len(cells) >= n else None for n in episodes], moved


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("campaigns", type=Path, nargs="+")
    ap.add_argument("--at", default="1500,5000", help="episode counts, comma-separated")
    ap.add_argument("--against", default="rpe", help="reference strategies, comma-separated")
    ap.add_argument("--seeds", help="only these seeds (8, 0-7 or 0,3)")
    args = ap.parse_args()
    at = [int(n) for n in args.at.split(",")]
    wanted = None if args.seeds is None else set(parse_seeds(args.seeds))
    table: dict[str, list[list[int | None]]] = {}
    names, moved = {}, {}
    for campaign in args.campaigns:
        for strat in sorted(p for p in campaign.iterdir() if p.is_dir() and p.name != "report"):
            runs = sorted(strat.glob("seed-*"), key=lambda p: int(p.name.split("-")[1]))
            runs = [r for r in runs if wanted is None or int(r.name.split("-")[1]) in wanted]
            runs = [r for r in runs if (r / METRICS_FILE).exists()]
            if not runs:
                continue
            label = strat.name if strat.name not in table else f"{strat.name} ({campaign.name})"
            read = [cells_at(r, at) for r in runs]
            table[label] = [cells for cells, _ in read]
            moved[label] = float(np.mean([share for _, share in read]))
            names[label] = ", ".join(r.name.split("-")[1] for r in runs)
    refs = [r for r in args.against.split(",") if r]
    print("| strategy | seeds | " + " | ".join(
        f"cells at {n} | mean ± sd | " + " | ".join(f"vs {r} (ratio, Welch p)" for r in refs)
        for n in at) + " | episodes that moved the ball |")  # fmt: skip
    print("|---|---|" + "---|---|" * len(at) + "---|" * len(at) * len(refs) + "---|")
    for label, rows in table.items():
        cells = [f"| {label} | {names[label]} |"]
        for k in range(len(at)):
            col = [r[k] for r in rows]
            got = np.array([c for c in col if c is not None], dtype=float)
            cells.append(" " + ", ".join("-" if c is None else str(c) for c in col) + " |")
            cells.append(f" {got.mean():.1f} ± {got.std(ddof=1):.1f} |" if len(got) > 1 else " |")
            for ref in refs:
                base = np.array([r[k] for r in table.get(ref, []) if r[k] is not None], float)
                if ref == label or len(base) < 2 or len(got) < 2:
                    cells.append(" |")
                    continue
                _, p = welch_vs_baseline(got, base)
                cells.append(f" {got.mean() / base.mean():.2f}x, p {p:.2g} |")
        cells.append(f" {100 * moved[label]:.1f}% |")
        print("".join(cells))


if __name__ == "__main__":
    main()
