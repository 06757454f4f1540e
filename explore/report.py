"""Figures and a one-page summary of a run or of a campaign of runs (matplotlib, Agg).

Every figure is ``FIG_PX`` = 960 x 640 pixels (9.6 x 6.4 in at 100 dpi), PNG.

A run report (``report_run``) writes into its output folder:
- ``coverage.png``: distinct ball and end-effector cells reached (of 30 x 30) against episodes.
- ``scatter.png``: end-effector positions at the end of each movement and ball positions after
  each episode, seen from above (m), coloured by episode (the paper's appendix style).
- ``goals.png``: only when the strategy set goals: goals and the outcomes reached (in the same
  goal-space coordinates) in 2-D projections of the goal space: one panel per module and pair
  of its coordinates (z0,z1), (z2,z3)... (up to ``MAX_GOAL_PANELS``).
- ``summary.md`` and ``summary.html`` (the HTML embeds the figures, so it stands alone).

A campaign is a folder ``CAMPAIGN/STRATEGY/RUN/`` (e.g. ``CAMPAIGN/rpe/seed-0/``). Its report
(``report_campaign``) writes ``campaign_coverage.png`` (ball cells: mean over seeds, +-1
standard deviation shaded, min and max dotted, per strategy), ``campaign_scatter.png`` (ball and
end-effector positions of all seeds, one column per strategy) and the summaries.

Runs are read without modifying them (safe while an exploration is still writing).
"""

from __future__ import annotations

import base64
import html
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from explore.metrics import ARENA_HALF_WIDTH, N_BINS, REACH_HALF_WIDTH, MetricsLog
from explore.recording import goal_outcome_of, iter_history, recording_paths
from explore.store import RunStore

FIG_PX = (960, 640)  # width, height of every figure, pixels
DPI = 100
FIGSIZE = (FIG_PX[0] / DPI, FIG_PX[1] / DPI)  # inches
N_CELLS = N_BINS * N_BINS
MAX_GOAL_PANELS = 6  # goals.png: panels (module, coordinate pair) at most


@dataclass
class RunData:
    """What a report needs from one run (N episodes).

    Attributes:
        episode, ball_cells, ee_cells, settle_s: (N,) per episode (cells reached so far).
        ball_moved: (N,) bool. kind: (N,) str. module: (N,) int.
        ball, context_ball: (N, 2) m, ball after / before each episode (NaN when not seen).
        ee_final: (N, 2) m, tool tip (x, y) at the end of each movement.
        goals: (N, g) goals, g = 0 when the strategy sets none (NaN-padded: a goal has the
            size of its module, g is the largest).
        reached: (N, g) each episode's outcome in its goal's coordinates (NaN where it has no
            goal or was not seen), or None when the run's goal space cannot be rebuilt
            (``explore.recording.goal_outcome_of``: engineered spaces, or a learned one whose
            model is still there).
    """

    path: Path
    meta: dict[str, Any]
    episode: np.ndarray
    ball_cells: np.ndarray
    ee_cells: np.ndarray
    settle_s: np.ndarray
    ball_moved: np.ndarray
    kind: np.ndarray
    module: np.ndarray
    ball: np.ndarray
    context_ball: np.ndarray
    ee_final: np.ndarray
    goals: np.ndarray
    reached: np.ndarray | None = None
    recordings: list[Path] = field(default_factory=list)

    @property
    def config(self) -> dict[str, Any]:
        return self.meta["config"]

    @property
    def n(self) -> int:
        return len(self.episode)

    @property
    def strategy(self) -> str:
        return str(self.config.get("strategy", {}).get("name", "?"))

    @property
    def seed(self) -> int:
        return int(self.config.get("seed", 0))

    def final(self) -> dict[str, float]:
        """Final figures: episodes, ball and end-effector cells, fraction that moved the ball."""
        return {
            "episodes": float(self.n),
            "ball_cells": float(self.ball_cells[-1]) if self.n else 0.0,
            "ee_cells": float(self.ee_cells[-1]) if self.n else 0.0,
            "moved_fraction": float(self.ball_moved.mean()) if self.n else 0.0,
        }


def load_run(path: Path, goal_outcomes: bool = True) -> RunData:
    """Read a run folder (config, history; metrics recomputed from the history).

    ``goal_outcomes``: also map each outcome into the run's goal space (``RunData.reached``,
    for the goals figure). For a latent run that encodes every outcome image with its VAE, the
    slow part of a report; campaign reports do without it.
    """
    path = Path(path)
    meta = RunStore.read_meta(path)
    metrics = MetricsLog(path / "metrics.csv")  # never written here
    cols: dict[str, list[Any]] = {k: [] for k in ("ball", "context_ball", "ee_final", "goals")}
    module, reached = [], []
    outcome_of = (
        goal_outcome_of(meta["config"].get("strategy", {}), load_models=True)
        if goal_outcomes
        else None
    )
    for rec in iter_history(path):
        metrics.update(rec)
        cols["ball"].append(np.asarray(rec.ball, dtype=float))
        cols["context_ball"].append(np.asarray(rec.context_ball, dtype=float))
        cols["ee_final"].append(np.asarray(rec.final_end_effector, dtype=float)[:2])
        cols["goals"].append(np.asarray(rec.goal, dtype=float).ravel())
        module.append(rec.module)
        reached.append(outcome_of(rec) if outcome_of and rec.goal.size else None)
    rows = metrics.rows
    g = max((len(x) for x in cols["goals"]), default=0)
    goals = np.full((len(rows), g), np.nan)
    for i, x in enumerate(cols["goals"]):
        goals[i, : len(x)] = x
    reached_arr = None
    if g and outcome_of is not None:
        reached_arr = np.full((len(rows), g), np.nan)
        for i, (x, r) in enumerate(zip(cols["goals"], reached, strict=True)):
            if r is not None and np.size(r) == len(x):
                reached_arr[i, : len(x)] = np.asarray(r, dtype=float).ravel()

    def col(name: str, dtype: Any = float) -> np.ndarray:
        return np.array([r[name] for r in rows], dtype=dtype)

    def pts(name: str) -> np.ndarray:
        return np.asarray(cols[name], dtype=float).reshape(-1, 2)

    return RunData(
        path=path,
        meta=meta,
        episode=col("episode", int),
        ball_cells=col("ball_cells"),
        ee_cells=col("ee_cells"),
        settle_s=col("settle_s"),
        ball_moved=col("ball_moved", int).astype(bool),
        kind=col("kind", str),
        module=np.asarray(module, dtype=int),
        ball=pts("ball"),
        context_ball=pts("context_ball"),
        ee_final=pts("ee_final"),
        goals=goals,
        reached=reached_arr,
        recordings=recording_paths(path),
    )


# ---- figures ---------------------------------------------------------------------------------
def _new_figure(ncols: int = 1, nrows: int = 1, **kw: Any) -> tuple[Any, Any]:
    return plt.subplots(nrows, ncols, figsize=FIGSIZE, dpi=DPI, layout="constrained", **kw)


def _save(fig: Any, out: Path) -> Path:
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=DPI)  # no bbox_inches="tight": the size stays FIG_PX
    plt.close(fig)
    return out


def _square(ax: Any, half: float, label: str) -> None:
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
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
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
    axes: Any, ee: np.ndarray, ball: np.ndarray, moved: np.ndarray, episode: np.ndarray | None
) -> Any:
    """End-effector (left) and ball (right) scatter, coloured by ``episode`` (N,) when given,
    else one colour; returns the end-effector scatter (for a colour bar)."""
    ax_ee, ax_ball = axes
    _square(ax_ee, REACH_HALF_WIDTH, f"end-effector grid (+-{REACH_HALF_WIDTH} m)")
    colour: dict[str, Any] = {"color": "tab:blue"}
    colour_moved: dict[str, Any] = {"color": "tab:orange"}
    if episode is not None:
        colour = {"c": episode, "cmap": "viridis"}
        colour_moved = {"c": episode[np.all(np.isfinite(ball), axis=1) & moved], "cmap": "viridis"}
    sc = ax_ee.scatter(ee[:, 0], ee[:, 1], s=6, **colour)
    _square(ax_ball, ARENA_HALF_WIDTH, f"arena square (+-{ARENA_HALF_WIDTH} m)")
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
    sc = _scatter_pair(axes, run.ee_final, run.ball, run.ball_moved, run.episode)
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


# ---- campaigns -------------------------------------------------------------------------------
def find_campaign_runs(campaign: Path) -> dict[str, list[Path]]:
    """Runs of a campaign, ``CAMPAIGN/STRATEGY/RUN/run.json``, by strategy folder name."""
    groups: dict[str, list[Path]] = {}
    for meta in sorted(Path(campaign).glob("*/*/run.json")):
        groups.setdefault(meta.parent.parent.name, []).append(meta.parent)
    return groups


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
        _scatter_pair((axes[0][c], axes[1][c]), ee, ball, moved, None)
        axes[0][c].set_title(f"{name}: end-effector ({len(runs)} seeds)", fontsize=10)
        axes[1][c].set_title(f"{name}: ball ({int(moved.sum())} moved)", fontsize=10)
    axes[1][0].legend(loc="upper right", fontsize=7)
    fig.suptitle("Outcomes seen from above, all seeds of each strategy")
    return _save(fig, out)


# ---- summaries -------------------------------------------------------------------------------
def _md_table(header: list[str], rows: list[list[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(lines)


def _run_markdown(run: RunData, figures: list[Path], out_dir: Path) -> str:
    f = run.final()
    cfg = run.config
    kinds = ", ".join(f"{k} {int((run.kind == k).sum())}" for k in sorted(set(run.kind.tolist())))
    rows = [
        ["episodes", f"{f['episodes']:.0f} (planned {cfg.get('episodes', '?')})"],
        ["ball cells reached", f"{f['ball_cells']:.0f} of {N_CELLS}"],
        ["end-effector cells reached", f"{f['ee_cells']:.0f} of {N_CELLS}"],
        [
            "episodes that moved the ball",
            f"{int(run.ball_moved.sum())} ({100 * f['moved_fraction']:.1f} %)",
        ],
        ["kinds", kinds or "-"],
        ["mean settle time", f"{run.settle_s.mean() if run.n else 0:.2f} s"],
    ]
    parts = [
        f"# Run report: {run.path.name}",
        "",
        f"Run folder `{run.path}`, created {run.meta.get('created', '?')}; strategy "
        f"**{run.strategy}**, seed {run.seed}, rig {cfg.get('rig', {}).get('name', '?')}.",
        "",
        "## Results",
        "",
        _md_table(["measure", "value"], rows),
        "",
        "## Figures",
        "",
    ]
    parts += [f"![{p.stem}]({p.relative_to(out_dir)})\n" for p in figures]
    parts += ["## Recording", ""]
    if run.recordings:
        files = " ".join(str(p) for p in run.recordings)
        parts += [f"Open it with `ergo replay {run.path}` or `rerun {files}`.", ""]
    else:
        parts += [f"No rerun recording; `ergo replay {run.path}` writes one from the history.", ""]
    parts += ["## Config", "", "```json", json.dumps(cfg, indent=2, sort_keys=True), "```", ""]
    return "\n".join(parts)


def _campaign_markdown(
    campaign: Path, groups: dict[str, list[RunData]], figures: list[Path], out_dir: Path
) -> str:
    from explore.campaign import welch_vs_baseline

    baseline = [r.final()["ball_cells"] for r in groups.get("rpe", [])]
    rows = []
    for name, runs in sorted(groups.items()):
        finals = [r.final() for r in runs]
        cells = np.array([x["ball_cells"] for x in finals])
        p = np.nan if name == "rpe" else welch_vs_baseline(cells, baseline)[1]  # nan: < 2 seeds
        ee = np.array([x["ee_cells"] for x in finals])
        moved = np.array([x["moved_fraction"] for x in finals])
        eps = sorted({int(x["episodes"]) for x in finals})
        rows.append(
            [
                name,
                str(len(runs)),
                "/".join(map(str, eps)),
                f"{cells.mean():.1f} +- {sample_std(cells):.1f} "
                f"[{cells.min():.0f}-{cells.max():.0f}]",
                f"{ee.mean():.1f} +- {sample_std(ee):.1f}",
                f"{100 * moved.mean():.1f} %",
                "" if np.isnan(p) else f"{p:.2g}",
            ]
        )
    parts = [
        f"# Campaign report: {campaign.name}",
        "",
        f"Campaign folder `{campaign}`: {sum(len(v) for v in groups.values())} runs.",
        "",
        "## Results (final values; mean +- std over seeds [min-max])",
        "",
        _md_table(
            [
                "strategy",
                "seeds",
                "episodes",
                "ball cells",
                "end-effector cells",
                "episodes that moved the ball",
                "Welch p vs rpe (ball cells)",
            ],
            rows,
        ),
        "",
        "## Figures",
        "",
    ]
    parts += [f"![{p.stem}]({p.relative_to(out_dir)})\n" for p in figures]
    parts += ["## Runs", ""]
    for name, runs in sorted(groups.items()):
        for r in runs:
            f = r.final()
            parts.append(
                f"- {name} `{r.path.name}` (seed {r.seed}): {f['episodes']:.0f} episodes, "
                f"{f['ball_cells']:.0f} ball cells"
            )
    parts.append("")
    return "\n".join(parts)


def markdown_to_html(md: str, base: Path) -> str:
    """A small converter for the summaries written here (headings, paragraphs, tables, images
    embedded as base64, code blocks, lists): no Markdown package needed."""
    out: list[str] = []
    lines = md.splitlines()
    i = 0
    while i < len(lines):
        line = lines[i]
        if line.startswith("```"):
            j = i + 1
            while j < len(lines) and not lines[j].startswith("```"):
                j += 1
            out.append("<pre>" + html.escape("\n".join(lines[i + 1 : j])) + "</pre>")
            i = j + 1
            continue
        if line.startswith("|"):
            rows = []
            while i < len(lines) and lines[i].startswith("|"):
                if not set(lines[i]) <= set("|-: "):
                    rows.append([c.strip() for c in lines[i].strip("|").split("|")])
                i += 1
            head, *body = rows
            out.append("<table><tr>" + "".join(f"<th>{_inline(c)}</th>" for c in head) + "</tr>")
            for r in body:
                out.append("<tr>" + "".join(f"<td>{_inline(c)}</td>" for c in r) + "</tr>")
            out.append("</table>")
            continue
        if line.startswith("!["):
            alt, _, rest = line[2:].partition("](")
            src = base / rest.rstrip(")")
            data = base64.b64encode(src.read_bytes()).decode("ascii")
            out.append(
                f'<p><img alt="{html.escape(alt)}" src="data:image/png;base64,{data}" '
                f'width="{FIG_PX[0]}" height="{FIG_PX[1]}"></p>'
            )
        elif line.startswith("#"):
            level = len(line) - len(line.lstrip("#"))
            out.append(f"<h{level}>{_inline(line[level:].strip())}</h{level}>")
        elif line.startswith("- "):
            out.append(f"<ul><li>{_inline(line[2:])}</li></ul>")
        elif line.strip():
            out.append(f"<p>{_inline(line)}</p>")
        i += 1
    body = "\n".join(out)
    title = html.escape(lines[0].lstrip("# ")) if lines else "report"
    style = (
        "body{font-family:sans-serif;max-width:1000px;margin:auto}"
        "table{border-collapse:collapse}td,th{border:1px solid #bbb;padding:3px 8px}"
        "pre{background:#f4f4f4;padding:8px}"
    )
    return (
        f"<!doctype html>\n<html><head><meta charset='utf-8'><title>{title}</title>"
        f"<style>{style}</style></head><body>\n{body}\n</body></html>\n"
    )


def _inline(text: str) -> str:
    """Escape, then `code` and **bold**."""
    import re

    t = html.escape(text)
    t = re.sub(r"`([^`]*)`", r"<code>\1</code>", t)
    return re.sub(r"\*\*([^*]*)\*\*", r"<b>\1</b>", t)


def _write_summaries(md: str, out_dir: Path) -> list[Path]:
    md_path, html_path = out_dir / "summary.md", out_dir / "summary.html"
    md_path.write_text(md)
    html_path.write_text(markdown_to_html(md, out_dir))
    return [md_path, html_path]


# ---- entry points ----------------------------------------------------------------------------
def report_run(run_path: Path, out_dir: Path | None = None) -> list[Path]:
    """Figures and summaries of one run; returns the files written (default ``RUN/report``)."""
    run = load_run(Path(run_path))
    out_dir = Path(out_dir) if out_dir is not None else run.path / "report"
    out_dir.mkdir(parents=True, exist_ok=True)
    figures = [
        coverage_figure(run, out_dir / "coverage.png"),
        scatter_figure(run, out_dir / "scatter.png"),
    ]
    goals = goals_figure(run, out_dir / "goals.png")
    if goals is not None:
        figures.append(goals)
    return figures + _write_summaries(_run_markdown(run, figures, out_dir), out_dir)


def report_campaign(campaign: Path, out_dir: Path | None = None) -> list[Path]:
    """Figures and summaries of a campaign folder (default ``CAMPAIGN/report``)."""
    campaign = Path(campaign)
    paths = find_campaign_runs(campaign)
    if not paths:
        raise FileNotFoundError(f"{campaign} holds no runs (expected CAMPAIGN/STRATEGY/RUN/)")
    groups = {
        name: [load_run(p, goal_outcomes=False) for p in runs] for name, runs in paths.items()
    }
    out_dir = Path(out_dir) if out_dir is not None else campaign / "report"
    out_dir.mkdir(parents=True, exist_ok=True)
    figures = [
        campaign_coverage_figure(groups, out_dir / "campaign_coverage.png"),
        campaign_scatter_figure(groups, out_dir / "campaign_scatter.png"),
    ]
    md = _campaign_markdown(campaign, groups, figures, out_dir)
    return figures + _write_summaries(md, out_dir)


def report(path: Path, out_dir: Path | None = None) -> list[Path]:
    """A run's report when ``path`` is a run folder, else a campaign's."""
    if RunStore.is_run(path):
        return report_run(path, out_dir)
    return report_campaign(path, out_dir)
