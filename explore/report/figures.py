"""Figures of runs and campaigns (matplotlib, Agg, headless).

Every report figure is ``FIG_PX`` = 960 x 640 pixels (9.6 x 6.4 in at 100 dpi), PNG:
- ``coverage_figure``: distinct ball and end-effector cells reached (of 30 x 30) against
  episodes;
- ``scatter_figure``: end-effector positions at the end of each movement and ball positions
  after each episode, seen from above (in the rig's unit: m, or the arm's reach on ArmBalls),
  coloured by episode (the paper's appendix style), over the squares of the rig's scene;
- ``goals_figure``: goals and the outcomes reached (in the same goal-space coordinates) in 2-D
  projections of the goal space: one panel per module and pair of its coordinates (z0,z1),
  (z2,z3)... (up to ``MAX_GOAL_PANELS``);
- ``campaign_coverage_figure``: ball cells, mean over seeds, +-1 standard deviation shaded, min
  and max dotted, per strategy; ``campaign_scatter_figure``: ball and end-effector positions of
  all seeds, one column per strategy.
``coverage_curve`` is the small ``RUN/coverage.png`` that ``ergo explore`` leaves at the end.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from explore.learner.scene import Scene
from explore.report.run_data import RunData
from explore.runs.layout import COVERAGE_FILE, METRICS_FILE
from explore.runs.metrics import N_BINS, read_metrics
from plumbing.files import atomic_write

FIG_PX = (960, 640)  # width, height of every figure, pixels
DPI = 100
FIGSIZE = (FIG_PX[0] / DPI, FIG_PX[1] / DPI)  # inches
N_CELLS = N_BINS * N_BINS
MAX_GOAL_PANELS = 6  # goals.png: panels (module, coordinate pair) at most


def _new_figure(ncols: int = 1, nrows: int = 1, **kw: Any) -> tuple[Any, Any]:
    return plt.subplots(nrows, ncols, figsize=FIGSIZE, dpi=DPI, layout="constrained", **kw)


def _save(fig: Any, out: Path) -> Path:
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=DPI)  # no bbox_inches="tight": the size stays FIG_PX
    plt.close(fig)
    return out


def _square(ax: Any, half: float, label: str, unit: str = "m") -> None:
    ax.plot(
        [-half, half, half, -half, -half],
        [-half, -half, half, half, -half],
        color="0.4",
        lw=1,
        label=label,
    )
    ax.set_xlim(-half * 1.05, half * 1.05)
    ax.set_ylim(-half * 1.05, half * 1.05)
    ax.set_aspect("equal")
    ax.set_xlabel(f"x ({unit})")
    ax.set_ylabel(f"y ({unit})")
    ax.grid(alpha=0.25)


def coverage_figure(run: RunData, out: Path) -> Path:
    """Ball and end-effector cells reached against episodes."""
    fig, ax = _new_figure()
    f = run.final()
    ax.plot(
        run.episode + 1,
        run.ball_cells,
        lw=2,
        drawstyle="steps-post",
        label=f"ball cells (final {f['ball_cells']:.0f})",
    )
    ax.plot(
        run.episode + 1,
        run.ee_cells,
        lw=1.5,
        alpha=0.8,
        drawstyle="steps-post",
        label=f"end-effector cells (final {f['ee_cells']:.0f})",
    )
    moved = run.episode[run.ball_moved] + 1
    if moved.size:
        ax.plot(
            moved,
            np.zeros_like(moved),
            "|",
            color="tab:orange",
            ms=10,
            label=f"episodes that moved the ball ({moved.size})",
        )
    ax.set_xlabel("episode")
    ax.set_ylabel(f"distinct cells reached (of {N_BINS} x {N_BINS} = {N_CELLS})")
    ax.set_title(f"Coverage: {run.path.name} ({run.strategy}, seed {run.seed})")
    ax.set_xlim(0, max(run.n, 1))
    ax.set_ylim(bottom=-1)
    ax.grid(alpha=0.3)
    ax.legend(loc="upper left")
    return _save(fig, out)


def _scatter_pair(
    axes: Any,
    ee: np.ndarray,
    ball: np.ndarray,
    moved: np.ndarray,
    episode: np.ndarray | None,
    scene: Scene,
) -> Any:
    """End-effector (left) and ball (right) scatter over the squares of ``scene``, coloured by
    ``episode`` (N,) when given, else one colour; returns the end-effector scatter (for a
    colour bar)."""
    ax_ee, ax_ball = axes
    h, u = scene.hand_half_width, scene.unit
    _square(ax_ee, h, f"end-effector grid (+-{h} {u})", u)
    colour: dict[str, Any] = {"color": "tab:blue"}
    colour_moved: dict[str, Any] = {"color": "tab:orange"}
    if episode is not None:
        colour = {"c": episode, "cmap": "viridis"}
        colour_moved = {"c": episode[np.all(np.isfinite(ball), axis=1) & moved], "cmap": "viridis"}
    sc = ax_ee.scatter(ee[:, 0], ee[:, 1], s=6, **colour)
    h = scene.ball_half_width
    _square(ax_ball, h, f"the metric's square (+-{h} {u})", u)
    ok = np.all(np.isfinite(ball), axis=1)
    ax_ball.scatter(
        ball[ok & ~moved, 0], ball[ok & ~moved, 1], s=14, color="0.6", label="ball not moved"
    )
    ax_ball.scatter(
        ball[ok & moved, 0],
        ball[ok & moved, 1],
        s=14,
        label="ball moved",
        **colour_moved,
    )
    return sc


def scatter_figure(run: RunData, out: Path) -> Path:
    """End-effector and ball positions from above, coloured by episode."""
    fig, axes = _new_figure(2)
    sc = _scatter_pair(axes, run.ee_final, run.ball, run.ball_moved, run.episode, run.scene)
    axes[0].set_title(f"End-effector at the end of each movement ({run.n})")
    axes[1].set_title(f"Ball after each episode ({int(run.ball_moved.sum())} moved it)")
    axes[0].legend(loc="upper right", fontsize=8)
    axes[1].legend(loc="upper right", fontsize=8)
    fig.colorbar(sc, ax=axes, label="episode", shrink=0.7)
    fig.suptitle(f"Outcomes seen from above: {run.path.name} ({run.strategy}, seed {run.seed})")
    return _save(fig, out)


def goal_panels(run: RunData) -> list[tuple[int, int, int]]:
    """The (module, i, j) coordinate pairs that ``goals_figure`` draws: for each module that
    set goals, (z0, z1), (z2, z3)... of its goal's coordinates (j = i for a trailing odd one),
    at most ``MAX_GOAL_PANELS`` in all."""
    panels: list[tuple[int, int, int]] = []
    if not run.goals.size:
        return panels
    has_goal = np.any(np.isfinite(run.goals), axis=1)
    for m in sorted(set(run.module[has_goal].tolist())):
        rows = has_goal & (run.module == m)
        d = int(np.isfinite(run.goals[rows]).sum(axis=1).max())
        panels += [(m, i, min(i + 1, d - 1)) for i in range(0, d, 2)]
    return panels[:MAX_GOAL_PANELS]


def goals_figure(run: RunData, out: Path) -> Path | None:
    """Goals (red) and the outcomes reached (green, same coordinates), in 2-D projections of
    the goal space: one panel per module and coordinate pair; None when the strategy set no
    goals."""
    panels = goal_panels(run)
    if not panels:
        return None
    n_modules = len({m for m, _, _ in panels})
    ncols = min(len(panels), 3)
    nrows = (len(panels) + ncols - 1) // ncols
    fig, axes = _new_figure(ncols, nrows, squeeze=False)
    for ax in axes.ravel()[len(panels) :]:
        ax.set_visible(False)
    n_goals = int(np.any(np.isfinite(run.goals), axis=1).sum())
    for ax, (m, i, j) in zip(axes.ravel(), panels, strict=False):
        rows = (run.module == m) & np.isfinite(run.goals[:, i])
        goals = run.goals[rows]
        ax.scatter(
            goals[:, i],
            goals[:, j] if j != i else np.zeros(len(goals)),
            s=8,
            color="tab:red",
            alpha=0.6,
            label="goals",
        )
        if run.reached is not None:
            r = run.reached[rows]
            ok = np.isfinite(r[:, i])
            ax.scatter(
                r[ok, i],
                r[ok, j] if j != i else np.zeros(int(ok.sum())),
                s=8,
                color="tab:green",
                alpha=0.6,
                label="reached",
            )
        ax.set_xlabel(f"z{i}")
        ax.set_ylabel(f"z{j}" if j != i else "(none)")
        where = f"module {m}: " if n_modules > 1 else ""
        ax.set_title(f"{where}z{i}, z{j}" if j != i else f"{where}z{i}", fontsize=10)
        ax.grid(alpha=0.3)
        ax.set_aspect("equal", adjustable="datalim")
    axes[0][0].legend(loc="upper right", fontsize=8)
    note = "" if run.reached is not None else " (goal space not rebuilt: no reached outcomes)"
    fig.suptitle(
        f"Goals and reached outcomes in the goal space ({run.strategy}): "
        f"{n_goals} goal episodes{note}"
    )
    return _save(fig, out)


def sample_std(a: np.ndarray, axis: int | None = None) -> np.ndarray:
    """Standard deviation over seeds with Bessel's correction (as summary.csv), 0 for one seed."""
    a = np.asarray(a, dtype=float)
    n = a.shape[axis] if axis is not None else a.size
    return a.std(axis=axis, ddof=1) if n > 1 else np.zeros_like(a.mean(axis=axis))


def campaign_coverage_figure(groups: dict[str, list[RunData]], out: Path) -> Path:
    """Ball cells against episodes: mean over seeds, +-1 std shaded, min/max dotted."""
    fig, ax = _new_figure()
    for k, (name, runs) in enumerate(sorted(groups.items())):
        n = min(r.n for r in runs)
        if n == 0:
            continue
        cells = np.stack([r.ball_cells[:n] for r in runs])
        x = np.arange(1, n + 1)
        mean, std = cells.mean(axis=0), sample_std(cells, axis=0)
        color = f"C{k}"
        ax.plot(
            x,
            mean,
            color=color,
            lw=2,
            label=f"{name}: mean of {len(runs)} seeds (final {mean[-1]:.1f} +- {std[-1]:.1f})",
        )
        ax.fill_between(x, mean - std, mean + std, color=color, alpha=0.2)
        ax.plot(x, cells.min(axis=0), color=color, ls=":", lw=1)
        ax.plot(x, cells.max(axis=0), color=color, ls=":", lw=1)
    ax.set_xlabel("episode")
    ax.set_ylabel(f"distinct ball cells reached (of {N_BINS} x {N_BINS} = {N_CELLS})")
    ax.set_title("Coverage by strategy: mean, +-1 std (shaded), min and max over seeds (dotted)")
    ax.set_ylim(bottom=0)
    ax.grid(alpha=0.3)
    ax.legend(loc="upper left")
    return _save(fig, out)


def campaign_scatter_figure(groups: dict[str, list[RunData]], out: Path) -> Path:
    """One column per strategy: end-effector (top) and ball (bottom) positions, all seeds."""
    names = sorted(groups)
    fig, axes = _new_figure(len(names), 2, squeeze=False)
    for c, name in enumerate(names):
        runs = groups[name]
        ee = np.concatenate([r.ee_final for r in runs])
        ball = np.concatenate([r.ball for r in runs])
        moved = np.concatenate([r.ball_moved for r in runs])
        _scatter_pair((axes[0][c], axes[1][c]), ee, ball, moved, None, runs[0].scene)
        axes[0][c].set_title(f"{name}: end-effector ({len(runs)} seeds)", fontsize=10)
        axes[1][c].set_title(f"{name}: ball ({int(moved.sum())} moved)", fontsize=10)
    axes[1][0].legend(loc="upper right", fontsize=7)
    fig.suptitle("Outcomes seen from above, all seeds of each strategy")
    return _save(fig, out)


def coverage_curve(run: Path, out: Path | None = None) -> Path:
    """Plot ball and end-effector cells reached against episodes; returns the PNG path."""
    m = read_metrics(run / METRICS_FILE)
    out = out or run / COVERAGE_FILE
    fig, ax = plt.subplots(figsize=(6.4, 4.0), dpi=100)
    ax.plot(m["episode"], m["ball_cells"], label="ball cells")
    ax.plot(m["episode"], m["ee_cells"], label="end-effector cells", alpha=0.7)
    ax.set_xlabel("episode")
    ax.set_ylabel(f"cells reached (of {N_BINS} x {N_BINS})")
    ax.set_title(f"Coverage: {run.name}")
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    try:  # a full disk leaves the previous figure, not half a new one
        atomic_write(out, fig.savefig)
    finally:
        plt.close(fig)
    return out
