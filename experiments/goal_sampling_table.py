"""The goal samplers' table: ball cells per (sampler, strategy) at given episodes, against
uniform RGE-EFR.

Reads folders of campaigns, one campaign per sampler,
``ROOT/SAMPLER/STRATEGY/seed-S/metrics.csv`` (``experiments/goal_sampling_final.sh`` writes them
so; several ROOTs are read as one). Per row: mean ± sd of the ball cells over seeds at each
checkpoint (the fraction of the 900 cells with ``--fraction``), each seed's figure, Welch's p
against uniform RGE-EFR's at the same checkpoint, and how many runs ended below uniform
RGE-EFR's mean at the last checkpoint.

    .venv/bin/python experiments/goal_sampling_table.py ROOT [ROOT ...] [--at 1500,5000] \\
        [--fraction]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from explore.campaigns.stats import welch_vs_baseline
from explore.runs.metrics import N_BINS, read_metrics

BASELINE = ("uniform", "rge-efr")


def cells_at(run: Path, at: list[int]) -> list[float] | None:
    """The run's ball cells after each of ``at`` episodes; None if it is shorter."""
    m = read_metrics(run / "metrics.csv")
    cells = m["ball_cells"]
    if len(cells) < max(at):
        return None
    return [float(cells[a - 1]) for a in at]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("roots", type=Path, nargs="+")
    ap.add_argument("--at", default="1500,5000", help="checkpoints, episodes")
    ap.add_argument("--fraction", action="store_true", help="fraction of the cells, not counts")
    args = ap.parse_args()
    at = [int(a) for a in args.at.split(",")]
    scale = 1.0 / (N_BINS * N_BINS) if args.fraction else 1.0
    table: dict[tuple[str, str], np.ndarray] = {}
    for run in sorted(r for root in args.roots for r in root.glob("*/*/seed-*")):
        got = cells_at(run, at)
        if got is not None:
            key = (run.parent.parent.name, run.parent.name)
            table[key] = np.vstack([table.get(key, np.zeros((0, len(at)))), [got]]) * 1.0
    if not table:
        where = ", ".join(map(str, args.roots))
        raise SystemExit(f"ergo: error: {where} holds no run of {max(at)} episodes")
    base = table.get(BASELINE)
    head = " | ".join(f"cells at {a} (p vs uniform rge-efr)" for a in at)
    print(f"| sampler | strategy | runs | {head} | below uniform rge-efr's mean |")
    print("|---|---|---|" + "---|" * len(at) + "---|")
    for (sampler, strategy), c in sorted(table.items()):
        cols = []
        for i in range(len(at)):
            p = welch_vs_baseline(c[:, i], base[:, i])[1] if base is not None else float("nan")
            each = ", ".join(f"{v * scale:.3g}" for v in c[:, i])
            sd = c[:, i].std(ddof=1) if len(c) > 1 else 0.0
            cols.append(f"{c[:, i].mean() * scale:.3g} ± {sd * scale:.2g} [{each}] (p {p:.2g})")
        below = int((c[:, -1] < base[:, -1].mean()).sum()) if base is not None else -1
        print(f"| {sampler} | {strategy} | {len(c)} | " + " | ".join(cols) + f" | {below} |")


if __name__ == "__main__":
    main()
