"""The reality gap of a run warmed by a prior (``RUN/reality_gap.csv``, explore/runs/prior.py):
for each arm episode whose parameters came from the prior, where the prior's episode left the
ball against where the arm's left it.

Two figures of the same pairs: the ball's final position (prior against arm; they also started
from different places), and its displacement (final minus start, which takes the start out).
An exploit episode played the prior episode's very parameters; an explore one added the
strategy's noise to them, so its gap is the noise's effect too.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from explore.runs.layout import REALITY_GAP_FILE


@dataclass
class Gap:
    """The pairs of a run's gap file.

    Attributes:
        episode: the arm's episodes, (n,).
        exploit: whether each was an exploit (the prior's parameters as they were), (n,).
        prior_start, prior_end, arm_start, arm_end: the ball before and after, (n, 2), in the
            scene's unit (NaN: not seen).
    """

    episode: np.ndarray
    exploit: np.ndarray
    prior_start: np.ndarray
    prior_end: np.ndarray
    arm_start: np.ndarray
    arm_end: np.ndarray

    @property
    def position(self) -> np.ndarray:
        """Distance between the prior's and the arm's final ball positions, (n,)."""
        return np.linalg.norm(self.prior_end - self.arm_end, axis=1)

    @property
    def displacement(self) -> np.ndarray:
        """Distance between the prior's and the arm's ball displacements, (n,)."""
        return np.linalg.norm(
            (self.prior_end - self.prior_start) - (self.arm_end - self.arm_start), axis=1
        )


def read_gap(run: Path) -> Gap | None:
    """The run's gap file, or None when it has none (not warmed) or no rows."""
    path = Path(run) / REALITY_GAP_FILE
    if not path.is_file():
        return None
    data = np.genfromtxt(path, delimiter=",", names=True, dtype=None, encoding="utf-8")
    data = np.atleast_1d(data)
    if data.size == 0 or data.dtype.names is None:
        return None

    def pair(prefix: str) -> np.ndarray:
        return np.column_stack([data[f"{prefix}_x"], data[f"{prefix}_y"]]).astype(float)

    return Gap(
        data["episode"].astype(int), data["kind"] == "exploit", pair("prior_context"),
        pair("prior"), pair("arm_context"), pair("arm"),
    )  # fmt: skip


def _median(values: np.ndarray, scale: float) -> str:
    ok = values[np.isfinite(values)]
    return f"{np.median(ok) * scale:.0f}" if len(ok) else "-"


def gap_line(run: Path, unit: str = "m") -> str | None:
    """One line on the run's reality gap, or None without one."""
    gap = read_gap(run)
    if gap is None:
        return None
    scale, shown = (1000.0, "mm") if unit == "m" else (1.0, unit)
    n, n_exploit = len(gap.episode), int(gap.exploit.sum())
    line = (
        f"{n} episodes played the prior's parameters ({n_exploit} as they were); prior against "
        f"arm, median distance of the ball's final position {_median(gap.position, scale)} "
        f"{shown}, of its displacement {_median(gap.displacement, scale)} {shown}"
    )
    if n_exploit:
        line += (
            f" (exploit episodes alone: {_median(gap.position[gap.exploit], scale)} and "
            f"{_median(gap.displacement[gap.exploit], scale)} {shown})"
        )
    return line


def gap_figure(run: Path, out: Path, half_width: float, unit: str = "m") -> Path | None:
    """``out``: the prior's final ball positions joined to the arm's for the same parameters
    (left), and the distances' distribution (right); None without a gap file."""
    gap = read_gap(run)
    if gap is None:
        return None
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    scale, shown = (1000.0, "mm") if unit == "m" else (1.0, unit)
    fig, (ax, hist) = plt.subplots(1, 2, figsize=(9.6, 4.8), dpi=100)
    for a, b in zip(gap.prior_end * scale, gap.arm_end * scale, strict=True):
        ax.plot([a[0], b[0]], [a[1], b[1]], color="0.6", lw=0.6)
    ax.scatter(*(gap.prior_end * scale).T, s=12, color="tab:blue", label="prior (twin)")
    ax.scatter(*(gap.arm_end * scale).T, s=12, color="tab:orange", label="arm")
    h = half_width * scale
    ax.set_xlim(-h, h)
    ax.set_ylim(-h, h)
    ax.set_aspect("equal")
    ax.set_xlabel(f"x ({shown})")
    ax.set_ylabel(f"y ({shown})")
    ax.set_title("ball after the same parameters", fontsize=10)
    ax.legend(fontsize=8)
    for values, label in ((gap.position, "final position"), (gap.displacement, "displacement")):
        ok = values[np.isfinite(values)] * scale
        if len(ok):
            hist.hist(ok, bins=20, alpha=0.6, label=f"{label} (median {np.median(ok):.0f})")
    hist.set_xlabel(f"prior against arm ({shown})")
    hist.set_ylabel("episodes")
    hist.set_title(f"reality gap, {len(gap.episode)} episodes", fontsize=10)
    hist.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out)
    plt.close(fig)
    return out
