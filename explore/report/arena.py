"""Where a run's goals and outcomes lie in the arena: is the ball confined to part of the ring,
and where were the goals aimed?

``arena_figure`` (a run report's ``arena.png``): left, the arena from above with the ball
after each episode (grey: random episodes; green: goal episodes) and the goals of the goal
episodes placed in the arena (red), the ring's 30-degree sectors that no moved ball entered
shaded; right, per sector, the goals aimed into it against the balls that ended there.
``confinement`` gives the same as figures for the report's table.

A goal is placed in the arena by its goal space: an engineered ball module's features are
inverted exactly (wrap-safe (r_n, cos t, sin t), polar (r_n, t / pi), cartesian (x / h, y / h));
any other module (a learned code, image positions) by an affine least-squares map of its
coordinates to the ball's (x, y), fitted on the run's own goal episodes (their reached
outcomes and balls), kept only where it explains ``MIN_R2`` of the ball's variance (a hand's
or a distractor's module does not locate the ball, and is left out).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from explore.learner.scene import Scene
from explore.report.figures import _new_figure, _save, _square
from explore.report.run_data import RunData

SECTOR_DEG = 30.0  # the ring's sectors: 12 of 30 degrees about the arena's centre (a choice)
N_SECTORS = 12  # 360 / SECTOR_DEG
MIN_R2 = 0.5  # a module's affine map to the ball is used from this R² on (a choice)


@dataclass
class Confinement:
    """A run's goals and outcomes in the arena.

    Attributes:
        goal_xy: (N, 2) each episode's goal in the arena (rig's unit), NaN where it has none
            or its module does not locate the ball.
        how: how goals were placed, e.g. "wrap-safe features" or "affine map, R² 0.93".
        sectors_reached: sectors (of ``N_SECTORS``) a moved ball ended in; None off a ring.
        goal_sectors, ball_sectors: (N_SECTORS,) goals aimed into each sector, moved balls
            that ended in it; None off a ring.
        goal_distance: median arena distance from a goal to its episode's ball (rig's unit),
            NaN without placed goals.
    """

    goal_xy: np.ndarray
    how: str
    sectors_reached: int | None
    goal_sectors: np.ndarray | None
    ball_sectors: np.ndarray | None
    goal_distance: float


def features_to_xy(z: np.ndarray, form: str, scene: Scene) -> np.ndarray:
    """Invert an engineered ball feature vector: (..., k) in ``form`` -> (..., 2) (x, y) in the
    scene's unit (``explore.learner.goal_spaces``: wrap-safe, polar or cartesian)."""
    z = np.asarray(z, dtype=float)
    if form == "cartesian":
        return z[..., :2] * scene.ball_half_width
    assert scene.ring is not None
    mid, half = (scene.ring[0] + scene.ring[1]) / 2, (scene.ring[1] - scene.ring[0]) / 2
    r = mid + half * z[..., 0]
    t = np.pi * z[..., 1] if form == "polar" else np.arctan2(z[..., 2], z[..., 1])
    return np.stack([r * np.cos(t), r * np.sin(t)], axis=-1)


def _affine_map(run: RunData, rows: np.ndarray, d: int) -> tuple[np.ndarray, float] | None:
    """Least-squares (d + 1, 2) map from a module's reached outcomes to the ball, and its R²,
    fitted on ``rows``; None without enough data."""
    if run.reached is None:
        return None
    x, y = run.reached[rows][:, :d], run.ball[rows]
    ok = np.all(np.isfinite(x), axis=1) & np.all(np.isfinite(y), axis=1)
    if ok.sum() < d + 3:
        return None
    design = np.c_[x[ok], np.ones(ok.sum())]
    fit, *_ = np.linalg.lstsq(design, y[ok], rcond=None)
    resid = y[ok] - design @ fit
    total = ((y[ok] - y[ok].mean(0)) ** 2).sum()
    return fit, float(1.0 - (resid**2).sum() / total) if total > 0 else 0.0


def goal_positions(run: RunData) -> tuple[np.ndarray, str]:
    """Each episode's goal in the arena, (N, 2), NaN where none, and how it was placed (module
    doc)."""
    assert run.goals is not None and run.module is not None and run.ball is not None
    out = np.full((run.n, 2), np.nan)
    if run.goals.shape[1] == 0:
        return out, "no goals"
    strategy = run.config.get("strategy", {})
    notes = []
    for m in sorted(set(run.module[run.module >= 0].tolist())):
        rows = (run.module == m) & np.any(np.isfinite(run.goals), axis=1)
        d = int(np.isfinite(run.goals[rows]).sum(axis=1).max()) if rows.any() else 0
        if d == 0:
            continue
        if str(strategy.get("name", "")).endswith("-efr") and m == 0:  # the ball's module
            form = strategy.get("options", {}).get("form") or run.scene.default_form
            out[rows] = features_to_xy(run.goals[rows][:, :d], form, run.scene)
            notes.append(f"{form} features")
            continue
        fitted = _affine_map(run, rows, d)
        if fitted is None or fitted[1] < MIN_R2:
            continue
        fit, r2 = fitted
        out[rows] = np.c_[run.goals[rows][:, :d], np.ones(rows.sum())] @ fit
        notes.append(f"module {m}: affine map, R² {r2:.2f}")
    return out, "; ".join(notes) or "no module locates the ball"


def sector_of(xy: np.ndarray) -> np.ndarray:
    """The ring sector (0..N_SECTORS-1, counter-clockwise from +x) of (n, 2) positions."""
    angle = np.degrees(np.arctan2(xy[:, 1], xy[:, 0])) % 360.0
    return np.minimum((angle // SECTOR_DEG).astype(int), N_SECTORS - 1)


def confinement(run: RunData) -> Confinement:
    """The run's ``Confinement`` (needs ``load_run(records=True)``)."""
    goal_xy, how = goal_positions(run)
    ball = run.ball
    assert ball is not None
    placed = np.all(np.isfinite(goal_xy), axis=1) & np.all(np.isfinite(ball), axis=1)
    dist = np.linalg.norm(goal_xy[placed] - ball[placed], axis=1)
    goal_distance = float(np.median(dist)) if dist.size else float("nan")
    if run.scene.ring is None:
        return Confinement(goal_xy, how, None, None, None, goal_distance)
    moved = run.ball_moved & np.all(np.isfinite(ball), axis=1)
    ball_sectors = np.bincount(sector_of(ball[moved]), minlength=N_SECTORS)
    has_goal = np.all(np.isfinite(goal_xy), axis=1)
    goal_sectors = np.bincount(sector_of(goal_xy[has_goal]), minlength=N_SECTORS)
    return Confinement(
        goal_xy, how, int((ball_sectors > 0).sum()), goal_sectors, ball_sectors, goal_distance
    )


def draw_arena(ax: Any, run: RunData, c: Confinement) -> None:
    """The arena from above on ``ax``: the ring and its sectors (those no moved ball entered
    shaded), the ball after each episode, the goals placed in the arena (module doc)."""
    ball, scene, u = run.ball, run.scene, run.scene.unit
    assert ball is not None
    has_goal = np.all(np.isfinite(c.goal_xy), axis=1)
    h = scene.ball_half_width
    _square(ax, h, f"the metric's square (+-{h} {u})", u)
    if scene.ring is not None:
        t = np.linspace(0, 2 * np.pi, 361)
        for r in scene.ring:
            ax.plot(r * np.cos(t), r * np.sin(t), color="0.3", lw=0.8)
        reach = scene.ring[1] * 1.05
        for k in range(N_SECTORS):
            a0 = np.radians(k * SECTOR_DEG)
            ax.plot([0, reach * np.cos(a0)], [0, reach * np.sin(a0)], color="0.8", lw=0.5)
            if c.ball_sectors is not None and c.ball_sectors[k] == 0:
                a = np.linspace(a0, a0 + np.radians(SECTOR_DEG), 20)
                ax.fill(np.r_[0, reach * np.cos(a)], np.r_[0, reach * np.sin(a)],
                        color="tab:red", alpha=0.08, lw=0)  # fmt: skip
    seen = np.all(np.isfinite(ball), axis=1)
    ax.scatter(*ball[seen & ~has_goal].T, s=5, color="0.65", label="ball, other episodes")
    ax.scatter(*ball[seen & has_goal].T, s=7, color="tab:green", alpha=0.6,
               label="ball after a goal episode")  # fmt: skip
    ax.scatter(*c.goal_xy[has_goal].T, s=4, color="tab:red", alpha=0.6, label="goals")
    ax.legend(loc="upper right", fontsize=7)
    reached = ""
    if c.sectors_reached is not None:
        reached = f"\nsectors a moved ball entered: {c.sectors_reached} of {N_SECTORS} (unshaded)"
    ax.set_title(f"Goals ({c.how}) and outcomes{reached}", fontsize=9)


def arena_figure(run: RunData, out: Path) -> Path | None:
    """The run's goals and outcomes over the arena (module doc); None for a run without goals
    placed in the arena."""
    c = confinement(run)
    if not np.all(np.isfinite(c.goal_xy), axis=1).any():
        return None
    u = run.scene.unit
    ring = run.scene.ring is not None
    fig, axes = _new_figure(2 if ring else 1, squeeze=False)
    draw_arena(axes[0][0], run, c)
    if ring and c.goal_sectors is not None and c.ball_sectors is not None:
        right = axes[0][1]
        centres = np.arange(N_SECTORS) * SECTOR_DEG + SECTOR_DEG / 2
        right.bar(centres - 6, c.goal_sectors, width=12, color="tab:red", label="goals aimed there")
        right.bar(centres + 6, c.ball_sectors, width=12, color="tab:green",
                  label="moved balls that ended there")  # fmt: skip
        right.set_xticks(np.arange(0, 361, 60))
        right.set_xlabel("sector: angle about the arena's centre (degrees)")
        right.set_ylabel("episodes")
        right.set_title(
            f"Per 30-degree sector; goal to outcome: {1000 * c.goal_distance:.0f} mm (median)"
            if u == "m" else f"Per sector; goal to outcome {c.goal_distance:.3f} {u}",
            fontsize=9,
        )  # fmt: skip
        right.legend(fontsize=8)
        right.grid(alpha=0.3)
    sampling = run.config.get("strategy", {}).get("options", {}).get("goal_sampling", "uniform")
    fig.suptitle(f"Goals and outcomes over the arena: {run.path.name} ({run.strategy}, "
                 f"goal_sampling {sampling}, seed {run.seed})")  # fmt: skip
    return _save(fig, out)
