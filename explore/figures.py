"""Figures of a run (matplotlib, headless)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

from explore.metrics import N_BINS, read_metrics


def coverage_curve(run: Path, out: Path | None = None) -> Path:
    """Plot ball and end-effector cells reached against episodes; returns the PNG path."""
    m = read_metrics(run / "metrics.csv")
    out = out or run / "coverage.png"
    fig, ax = plt.subplots(figsize=(6.4, 4.0), dpi=100)
    ax.plot(m["episode"], m["ball_cells"], label="ball cells")
    ax.plot(m["episode"], m["ee_cells"], label="end-effector cells", alpha=0.7)
    ax.set_xlabel("episode")
    ax.set_ylabel(f"cells reached (of {N_BINS} x {N_BINS})")
    ax.set_title(f"Coverage: {run.name}")
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(out)
    plt.close(fig)
    return out
