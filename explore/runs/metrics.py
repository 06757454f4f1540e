"""Exploration metric: distinct cells reached on a grid over the square of the rig's scene.

The paper's measure (docs/facts.md): ball positions binned into 30 x 30 cells over the
arena's square, performance = number of non-empty cells. End-effector positions are counted
the same way over the arm's reach, for the paper's scatter plots. The square and the reach are
the run's rig's scene's (``explore.learner.scene.Scene``, given: the twin's arena, +-0.2 m and
the Ergo Jr's reach, explore/rigs/arena.py; ArmBalls' square [-1, 1]^2, where this count over
900 is the CoRL 2018 campaign's exploration ratio, docs/armballs.md).

``exploration_ratio`` and ``checkpoints`` give that campaign's curves: the fraction of the
cells holding the final ball position of at least one of the first n episodes (bootstrap
included), at n = int(i x 10000 / 30).
"""

from __future__ import annotations

import csv
import io
from pathlib import Path

import numpy as np

from explore.learner.scene import Scene
from explore.runs.layout import METRICS_FILE
from plumbing.files import atomic_write

N_BINS = 30  # paper
# The published curves' checkpoints: int(i * 10000 / 30), i = 0..29 (results/
# Experiment_Visualization.ipynb of the CoRL 2018 campaign; docs/armballs.md)
CHECKPOINT_SPAN, CHECKPOINT_COUNT = 10000, 30


class CellCounter:
    """Counts distinct cells of an ``n_bins`` x ``n_bins`` grid over [-h, h]^2 (the scene's
    unit: metres on the Ergo Jr rigs).

    Points outside the square or NaN (not seen) are ignored.
    """

    def __init__(self, half_width: float, n_bins: int = N_BINS) -> None:
        self.half_width = half_width
        self.n_bins = n_bins
        self.grid = np.zeros((n_bins, n_bins), dtype=bool)

    def cells_of(self, points: np.ndarray) -> np.ndarray:
        """Cell indices (i along x, j along y) of points inside the closed square [-h, h]^2,
        shape (k, 2). Which points are inside is decided on the coordinates themselves, then
        the index is clipped into the grid: a point an ulp inside the far edge whose scaled
        coordinate rounds up to ``n_bins`` belongs to the last cell, as the edge itself."""
        p = np.asarray(points, dtype=float).reshape(-1, 2)
        h = self.half_width
        p = p[np.all((p >= -h) & (p <= h), axis=1)]  # NaN: never inside
        idx = np.floor((p + h) / (2 * h) * self.n_bins).astype(int)
        return np.clip(idx, 0, self.n_bins - 1)

    def add(self, points: np.ndarray) -> int:
        """Mark the cells of ``points`` (k, 2) m; returns the count of cells reached so far."""
        idx = self.cells_of(points)
        self.grid[idx[:, 0], idx[:, 1]] = True
        return self.count

    @property
    def count(self) -> int:
        return int(self.grid.sum())


METRIC_COLUMNS = ("episode", "ball_cells", "ee_cells", "ball_moved", "kind", "settle_s")


class MetricsLog:
    """Cells reached after every episode, kept in memory and appended to ``metrics.csv``; the
    grids are over the run's rig's ``scene`` (its ball and hand half widths)."""

    def __init__(self, path: Path, scene: Scene) -> None:
        self.path = path
        self.ball = CellCounter(scene.ball_half_width)
        self.ee = CellCounter(scene.hand_half_width)
        self.rows: list[dict[str, object]] = []

    def update(self, record: object) -> dict[str, object]:
        """Count one ``EpisodeRecord``; returns its metrics row."""
        row = {
            "episode": record.episode,  # type: ignore[attr-defined]
            "ball_cells": self.ball.add(record.ball),  # type: ignore[attr-defined]
            "ee_cells": self.ee.add(record.final_end_effector[:2]),  # type: ignore[attr-defined]
            "ball_moved": int(record.ball_moved),  # type: ignore[attr-defined]
            "kind": record.kind,  # type: ignore[attr-defined]
            "settle_s": round(record.settle_s, 3),  # type: ignore[attr-defined]
        }
        self.rows.append(row)
        return row

    def rewrite(self) -> None:
        """Write every row so far (used after a resume rebuilt them from the history)."""
        buf = io.StringIO(newline="")
        w = csv.DictWriter(buf, fieldnames=METRIC_COLUMNS)
        w.writeheader()
        w.writerows(self.rows)
        atomic_write(self.path, buf.getvalue())

    def append_last(self) -> None:
        new = not self.path.exists()
        with open(self.path, "a", newline="") as f:
            w = csv.DictWriter(f, fieldnames=METRIC_COLUMNS)
            if new:
                w.writeheader()
            w.writerow(self.rows[-1])


def read_metrics(path: Path) -> dict[str, np.ndarray]:
    """Read a ``metrics.csv`` into columns (numbers as arrays)."""
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    out: dict[str, np.ndarray] = {}
    for col in METRIC_COLUMNS:
        vals = [r[col] for r in rows]
        out[col] = np.array(vals) if col == "kind" else np.array(vals, dtype=float)
    return out


def recorded_episodes(run: Path) -> int | None:
    """Episodes ``RUN/metrics.csv`` says the run had stored (its last episode + 1), or None
    without a readable file. The writer appends a row after each episode it stored, and
    rewrites the file from the history on resume, so more than the history holds means the
    history lost some (cut short, emptied, deleted)."""
    try:
        with open(Path(run) / METRICS_FILE, newline="") as f:
            episodes = [int(r["episode"]) for r in csv.DictReader(f)]
    except (OSError, ValueError, KeyError, TypeError, csv.Error):
        return None
    return max(episodes) + 1 if episodes else 0


def checkpoints(span: int = CHECKPOINT_SPAN, count: int = CHECKPOINT_COUNT) -> np.ndarray:
    """Episode counts n = int(i * span / count), i = 0..count-1 (0, 333, ..., 9666)."""
    return np.array([int(i * span / count) for i in range(count)])


def exploration_ratio(ball_cells: np.ndarray, n: np.ndarray, n_bins: int = N_BINS) -> np.ndarray:
    """The fraction of the ``n_bins`` x ``n_bins`` cells holding a final ball position of one of
    the first ``n`` episodes, from a run's ``ball_cells`` column (row k: after episode k);
    NaN where the run holds fewer than n episodes. Shape of ``n``."""
    cells = np.asarray(ball_cells, dtype=float)
    n = np.asarray(n, dtype=int)
    out = np.full(n.shape, np.nan)
    for idx, k in np.ndenumerate(n):
        if k == 0:
            out[idx] = 0.0
        elif 0 < k <= len(cells):
            out[idx] = cells[k - 1] / n_bins**2
    return out
