"""Exploration metric: distinct cells reached on a grid over the arena's bounding square.

The paper's measure (docs/facts.md): ball positions binned into 30 x 30 cells over the
arena's square, performance = number of non-empty cells. End-effector positions are counted
the same way over the arm's reach, for the paper's scatter plots.
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from robot.spec import ERGO_JR_REACH_M
from sim.models.make_scene import ARENA_RADIUS

N_BINS = 30  # paper
# Bounding square of the ball's arena: the outer wall's inner radius (the twin's, and the rig's
# as built: sim/models/make_scene.py), m.
ARENA_HALF_WIDTH = ARENA_RADIUS
# End-effector grid: the arm's horizontal reach (robot/spec.py), m.
REACH_HALF_WIDTH = ERGO_JR_REACH_M


class CellCounter:
    """Counts distinct cells of an ``n_bins`` x ``n_bins`` grid over [-h, h]^2 (metres).

    Points outside the square or NaN (not seen) are ignored.
    """

    def __init__(self, half_width: float, n_bins: int = N_BINS) -> None:
        self.half_width = half_width
        self.n_bins = n_bins
        self.grid = np.zeros((n_bins, n_bins), dtype=bool)

    def cells_of(self, points: np.ndarray) -> np.ndarray:
        """Cell indices (i along x, j along y) of points inside the square, shape (k, 2)."""
        p = np.asarray(points, dtype=float).reshape(-1, 2)
        p = p[np.all(np.isfinite(p), axis=1)]
        idx = np.floor((p + self.half_width) / (2 * self.half_width) * self.n_bins).astype(int)
        # the square's far edges belong to the last cell
        idx[(p == self.half_width)] = self.n_bins - 1
        inside = np.all((idx >= 0) & (idx < self.n_bins), axis=1)
        return idx[inside]

    def add(self, points: np.ndarray) -> int:
        """Mark the cells of ``points`` (k, 2) m; returns the count of cells reached so far."""
        idx = self.cells_of(points)
        self.grid[idx[:, 0], idx[:, 1]] = True
        return self.count

    @property
    def count(self) -> int:
        return int(self.grid.sum())


METRICS_FILE = "metrics.csv"  # in the run folder
METRIC_COLUMNS = ("episode", "ball_cells", "ee_cells", "ball_moved", "kind", "settle_s")


class MetricsLog:
    """Cells reached after every episode, kept in memory and appended to ``metrics.csv``."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.ball = CellCounter(ARENA_HALF_WIDTH)
        self.ee = CellCounter(REACH_HALF_WIDTH)
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
        tmp = self.path.with_name(self.path.name + ".tmp")
        with open(tmp, "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=METRIC_COLUMNS)
            w.writeheader()
            w.writerows(self.rows)
        tmp.replace(self.path)

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
