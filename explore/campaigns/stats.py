"""What a campaign found: final ball cells per run and per strategy over seeds, Welch's t-test
against the RPE baseline, ``CAMPAIGN/summary.csv`` and the printed table."""

from __future__ import annotations

import csv
from pathlib import Path
from typing import Any

from explore.runs.layout import METRICS_FILE


def final_cells(run_dir: Path) -> tuple[int, int]:
    """(episodes, final ball cells) of a run from its metrics.csv; (0, 0) when absent."""
    from explore.runs.metrics import read_metrics

    path = run_dir / METRICS_FILE
    if not path.exists():
        return 0, 0
    m = read_metrics(path)
    if len(m["episode"]) == 0:
        return 0, 0
    return len(m["episode"]), int(m["ball_cells"][-1])


def welch_vs_baseline(cells: Any, baseline: Any) -> tuple[float, float]:
    """Welch's t-test (unequal variances) of final cells against the baseline's (RPE), two-sided.

    Returns (t, p); NaN when either side has fewer than 2 seeds or both have no spread.
    """
    import warnings

    import numpy as np
    from scipy import stats

    a, b = np.asarray(cells, dtype=float), np.asarray(baseline, dtype=float)
    if len(a) < 2 or len(b) < 2 or (a.std() == 0 and b.std() == 0):
        return float("nan"), float("nan")
    with warnings.catch_warnings():  # one side without spread (all seeds equal) is fine here
        warnings.simplefilter("ignore", RuntimeWarning)
        res = stats.ttest_ind(a, b, equal_var=False)
    return float(res.statistic), float(res.pvalue)


def write_summary(out: Path, strategies: list[str], seeds: list[int]) -> list[dict[str, Any]]:
    """Final ball cells per strategy over seeds, and Welch's t-test of each against ``rpe``
    (when the campaign has it) -> ``out/summary.csv``; returns the rows."""
    import numpy as np

    rows = []
    finals = {}
    for s in strategies:
        per_seed = [final_cells(out / s / f"seed-{seed}") for seed in seeds]
        finals[s] = np.array([c for _, c in per_seed], dtype=float)
        cells = finals[s]
        rows.append({
            "strategy": s,
            "seeds": len(seeds),
            "episodes": min(n for n, _ in per_seed),
            "cells_mean": round(float(cells.mean()), 2),
            "cells_std": round(float(cells.std(ddof=1)) if len(cells) > 1 else 0.0, 2),
            "cells_per_seed": " ".join(str(int(c)) for c in cells),
        })  # fmt: skip
    for r in rows:
        t, pval = (float("nan"), float("nan"))
        if "rpe" in finals and r["strategy"] != "rpe":
            t, pval = welch_vs_baseline(finals[r["strategy"]], finals["rpe"])
        r["welch_t_vs_rpe"] = round(t, 3)
        r["welch_p_vs_rpe"] = round(pval, 4)
    with open(out / "summary.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    return rows


def format_table(rows: list[dict[str, Any]]) -> str:
    head = (
        f"{'strategy':<14} {'episodes':>8} {'ball cells (mean ± std)':>24} {'Welch p vs rpe':>15}"
    )
    lines = [head + "  per seed"]
    for r in rows:
        cells = f"{r['cells_mean']:.1f} ± {r['cells_std']:.1f}"
        p = r.get("welch_p_vs_rpe", float("nan"))
        ptxt = "" if p != p else f"{p:.4f}"  # NaN: no test (rpe itself, or too few seeds)
        lines.append(
            f"{r['strategy']:<14} {r['episodes']:>8} {cells:>24} {ptxt:>15}  {r['cells_per_seed']}"
        )
    return "\n".join(lines)
