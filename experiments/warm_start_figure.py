"""The warm-start campaign's table and figure (docs/warm_start.md, "Measured"), from the
folders ``experiments/warm_start_campaign.py`` wrote: per bus and stand-in, the ball cells
after 60, 100 and 300 episodes from scratch, warmed by the nominal twin and by the fitted
twin, with the share of episodes that moved the ball, the reality gap of each warmed run and
every part's wall time; the figure draws the ball cells against episodes, a panel per rig.

    .venv/bin/python experiments/warm_start_figure.py OUT [OUT ...] [--figure PNG]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from explore.report.reality_gap import read_gap
from explore.runs.metrics import read_metrics

ARMS = ("scratch", "nominal", "fitted")
AT = (60, 100, 300)


def curve(run: Path) -> list[int]:
    """The run's ball cells after each episode (empty if it has no metrics)."""
    path = run / "metrics.csv"
    return [int(c) for c in read_metrics(path)["ball_cells"]] if path.is_file() else []


def gap_cell(run: Path) -> str:
    """The warmed run's episodes answered by the prior; median gap of the ball's final position
    and of its displacement, mm (its ``reality_gap.csv``, explore/report/reality_gap.py)."""
    gap = read_gap(run)
    if gap is None:
        return ""
    position, displacement = np.nanmedian(gap.position), np.nanmedian(gap.displacement)
    return f"{len(gap.episode)}; {position * 1000:.0f} / {displacement * 1000:.0f} mm"


def rows_of(outs: list[Path]) -> list[tuple[dict, Path, dict[str, list[int]]]]:
    """Each bus rig's campaign row, its folder and each arm's ball cells per episode."""
    found = [
        (json.loads(f.read_text()), f.parent.parent) for o in outs for f in o.glob("rows/*.json")
    ]
    rows = sorted(
        (r for r in found if r[0]["bus"] != "hidden"), key=lambda r: (r[0]["bus"], r[0]["stand-in"])
    )
    return [(r, out, {a: curve(out / run_name(r, a)) for a in ARMS}) for r, out in rows]


def run_name(row: dict, arm: str) -> str:
    return f"run-{arm}-{row['bus']}-{row['stand-in']}-e0"


def table(rows: list[tuple[dict, Path, dict[str, list[int]]]]) -> str:
    head = ["bus", "stand-in", *(f"{a}: cells at 60 / 100 / 300 (moved)" for a in ARMS)]
    head += ["nominal prior: answered; gap, final / displacement", "fitted prior: the same"]
    head += ["wall s: calibrations, dynamics fit, twin runs (nominal, fitted), bus runs"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r, out, curves in rows:
        bus, seed = r["bus"], r["stand-in"]
        cells = []
        for arm in ARMS:
            c = curves[arm]
            got = " / ".join(str(c[n - 1]) if len(c) >= n else "-" for n in AT)
            cells.append(f"{got} ({round(100 * r.get(f'{arm} moved', 0))} %)")
        gaps = [gap_cell(out / run_name(r, arm)) for arm in ("nominal", "fitted")]
        wall = [r.get("calibrations s", "-"), r.get("dynamics s", "-")]
        wall += [f"{r.get('nominal twin s', '-')}, {r.get('fitted twin s', '-')}"]
        wall += [", ".join(str(r.get(f"{a} s", "-")) for a in ARMS)]
        lines.append(
            "| " + " | ".join([bus, str(seed), *cells, *gaps, " / ".join(map(str, wall))]) + " |"
        )
    return "\n".join(lines)


def figure(rows: list[tuple[dict, Path, dict[str, list[int]]]], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ncols = min(3, len(rows))
    nrows = -(-len(rows) // ncols)
    fig, axes = plt.subplots(
        nrows, ncols, figsize=(3.2 * ncols, 2.8 * nrows), sharey=True, squeeze=False
    )
    for ax in axes.flat[len(rows) :]:
        ax.set_visible(False)
    for ax, (r, _, curves) in zip(axes.flat, rows, strict=False):
        for arm, colour in zip(ARMS, ("0.5", "tab:blue", "tab:orange"), strict=True):
            c = curves[arm]
            ax.plot(range(1, len(c) + 1), c, color=colour, label=arm)
        ax.set_title(f"stand-in {r['stand-in']}, {r['bus']}", fontsize=9)
        ax.set_xlabel("episodes on the arm")
    for row in axes:
        row[0].set_ylabel("ball cells")
    axes[0][0].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=90)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("outs", type=Path, nargs="+", help="folders of warm_start_campaign.py")
    ap.add_argument("--figure", type=Path, help="where to draw the ball cells against episodes")
    args = ap.parse_args()
    rows = rows_of(args.outs)
    if not rows:
        raise SystemExit(f"ergo: error: no campaign row under {', '.join(map(str, args.outs))}")
    print(table(rows))
    if args.figure:
        figure(rows, args.figure)


if __name__ == "__main__":
    main()
