"""A one-page summary (Markdown, and HTML that embeds the figures) of a run or of a campaign
of runs, with its figures (explore/report/figures.py).

A run report (``report_run``) writes into its output folder ``coverage.png``, ``scatter.png``,
``goals.png`` and ``arena.png`` (only when the strategy set goals; ``arena.png``: goals and
outcomes over the arena, explore/report/arena.py), ``summary.md`` and ``summary.html``.

A campaign is a folder ``CAMPAIGN/STRATEGY/RUN/`` (e.g. ``CAMPAIGN/rpe/seed-0/``). Its report
(``report_campaign``) writes ``campaign_coverage.png`` and the summaries from each run's
``metrics.csv`` (seconds, whatever the campaign's size), and with ``scatter=True`` also
``campaign_scatter.png``, which needs every episode's record decoded (minutes for 100k
episodes).

A report is written into a hidden folder beside its output folder (``.NAME.partial``), then its
files are moved in: a report stopped while drawing leaves the output folder as it was; one
stopped while moving (milliseconds) leaves ``REPORT_INCOMPLETE`` in it, which a complete report
removes.
"""

from __future__ import annotations

import base64
import html
import json
import logging
import os
import shutil
from collections.abc import Iterator
from contextlib import contextmanager
from datetime import datetime
from pathlib import Path

import numpy as np

from explore.report.arena import N_SECTORS, arena_figure, confinement
from explore.report.figures import (
    FIG_PX,
    N_CELLS,
    campaign_coverage_figure,
    campaign_scatter_figure,
    coverage_figure,
    goals_figure,
    sample_std,
    scatter_figure,
)
from explore.report.reality_gap import gap_figure, gap_line
from explore.report.run_data import RunData, find_campaign_runs, load_run
from explore.runs.layout import COVERAGE_FILE, INPUTS_KEY
from explore.runs.store import RunStore

log = logging.getLogger(__name__)

INCOMPLETE = "REPORT_INCOMPLETE"  # in an output folder whose report stopped being moved in
# every file a report may write: those this report did not write are stale, removed
REPORT_FILES = (COVERAGE_FILE, "scatter.png", "goals.png", "arena.png", "reality_gap.png",
                "campaign_coverage.png", "campaign_scatter.png",
                "summary.md", "summary.html")  # fmt: skip


# ---- summaries -------------------------------------------------------------------------------
def _md_table(header: list[str], rows: list[list[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(lines)


def empty_cells_notes(run: RunData) -> list[str]:
    """Why a run's ball or end-effector cells were never counted, and what to run, one
    sentence each (none when both were counted in some episode, or nothing was read).

    The ball: a physical rig locates it with the tracker of its arena calibration; without one
    (``run.json``'s inputs hold no ``arena``) every ball position is unknown. The end
    effector: a physical rig's camera tracks the ball only, so its tool tip is never known
    (``explore.rigs.ball.CameraSensor.tool_tip``); the twin's is."""
    if not run.n or not run.has_records:
        return []
    from explore.rigs.rig import RigError, is_physical

    rig = run.config.get("rig", {})
    name, rig_id = rig.get("name", "sim"), rig.get("rig_id", "?")
    try:
        physical = is_physical(name)
    except RigError:  # a rig this version does not know
        physical = False
    notes = []
    if not np.isfinite(run.ball).all(axis=1).any():
        kinds = {i.get("kind") for i in run.meta.get(INPUTS_KEY) or [] if isinstance(i, dict)}
        if physical and "arena" not in kinds:
            notes.append(
                f"No ball position was recorded: rig {name!r} (rig id {rig_id}) had no arena "
                "calibration, so the camera could not locate the ball and the ball cells "
                f"cannot be counted. Run `ergo calibrate arena --rig-id {rig_id} --camera ...` "
                "(docs/calibration.md), then explore again."
            )
        else:
            notes.append(
                f"No ball position was recorded: the ball was not seen in any of the {run.n} "
                "episodes, so the ball cells cannot be counted. Check the camera's view of the "
                "ball with `ergo track --camera ... --arena FILE` (the arena calibration)."
            )
    if physical and not np.isfinite(run.ee_final).all(axis=1).any():
        notes.append(
            f"No end-effector position was recorded: rig {name!r}'s camera tracks the ball "
            "only, so the tool tip's cells are not counted on a physical rig (the twin, "
            "`--rig sim`, counts them)."
        )
    return notes


def _run_markdown(run: RunData, figures: list[Path], out_dir: Path) -> str:
    f = run.final()
    cfg = run.config
    kinds = ", ".join(f"{k} {int((run.kind == k).sum())}" for k in sorted(set(run.kind.tolist())))
    rows = [
        ["episodes", f"{f['episodes']:.0f} (planned {run.planned_episodes})"],
        ["ball cells reached", f"{f['ball_cells']:.0f} of {N_CELLS}"],
        ["end-effector cells reached", f"{f['ee_cells']:.0f} of {N_CELLS}"],
        [
            "episodes that moved the ball",
            f"{int(run.ball_moved.sum())} ({100 * f['moved_fraction']:.1f} %)",
        ],
        ["kinds", kinds or "-"],
        ["mean settle time", f"{run.settle_s.mean() if run.n else 0:.2f} s"],
    ]
    gap = gap_line(run.path, run.scene.unit)  # a run warmed by a prior (docs/warm_start.md)
    if gap is not None:
        rows.append(["reality gap (the prior's outcome against the arm's)", gap])
    if run.has_records and run.goals is not None and run.goals.shape[1]:
        c = confinement(run)
        if c.sectors_reached is not None:
            rows.append(
                ["ring sectors a moved ball entered", f"{c.sectors_reached} of {N_SECTORS}"]
            )
        if np.isfinite(c.goal_distance):
            unit = run.scene.unit
            dist = (f"{1000 * c.goal_distance:.0f} mm" if unit == "m"
                    else f"{c.goal_distance:.3f} {unit}")  # fmt: skip
            rows.append(["goal to outcome in the arena, median", f"{dist} ({c.how})"])
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
    ]
    for note in empty_cells_notes(run):
        parts += [note, ""]
    parts += [
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
    from explore.campaigns.stats import welch_vs_baseline

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
    if not any(p.name == "campaign_scatter.png" for p in figures):
        parts += [
            "The table and the figure above come from the runs' `metrics.csv`. The scatter of "
            "every episode's end-effector and ball positions needs every record read (minutes "
            f"for 100k episodes): `ergo report {campaign} --scatter`.",
            "",
        ]
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


@contextmanager
def _staged(out_dir: Path) -> Iterator[tuple[Path, list[Path]]]:
    """(a folder to write the report into, the list of its files): at the end the files are
    moved into ``out_dir`` (under ``REPORT_INCOMPLETE``, then removed) and the list rewritten
    to their final paths. Stopped before the end, ``out_dir`` is as it was."""
    out_dir.parent.mkdir(parents=True, exist_ok=True)
    tmp = out_dir.parent / f".{out_dir.name}.partial"
    if tmp.exists():
        shutil.rmtree(tmp)  # what a stopped report left (never the report itself)
    tmp.mkdir()
    written: list[Path] = []
    try:
        yield tmp, written
        out_dir.mkdir(exist_ok=True)
        marker = out_dir / INCOMPLETE
        marker.write_text(
            f"ergo report started moving a new report into this folder at {datetime.now()} "
            "and stopped before the end: its files are a mix of two reports; run it again.\n"
        )
        names = {p.name for p in written}
        for name in REPORT_FILES:
            if name not in names:
                (out_dir / name).unlink(missing_ok=True)  # a figure this report has not
        for p in written:
            os.replace(p, out_dir / p.name)
        written[:] = [out_dir / p.name for p in written]
        marker.unlink()
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


# ---- entry points ----------------------------------------------------------------------------
def report_run(run_path: Path, out_dir: Path | None = None) -> list[Path]:
    """Figures and summaries of one run; returns the files written (default ``RUN/report``)."""
    run = load_run(Path(run_path))
    out_dir = Path(out_dir) if out_dir is not None else run.path / "report"
    with _staged(out_dir) as (tmp, written):
        figures = [
            coverage_figure(run, tmp / COVERAGE_FILE),
            scatter_figure(run, tmp / "scatter.png"),
        ]
        goals = goals_figure(run, tmp / "goals.png")
        if goals is not None:
            figures.append(goals)
            arena = arena_figure(run, tmp / "arena.png")
            if arena is not None:
                figures.append(arena)
        scene = run.scene
        gap = gap_figure(run.path, tmp / "reality_gap.png", scene.ball_half_width, scene.unit)
        if gap is not None:
            figures.append(gap)
        written += figures + _write_summaries(_run_markdown(run, figures, tmp), tmp)
    for note in empty_cells_notes(run):
        log.warning("%s: %s", run.path, note)
    return written


def report_campaign(
    campaign: Path, out_dir: Path | None = None, scatter: bool = False
) -> list[Path]:
    """Figures and summaries of a campaign folder (default ``CAMPAIGN/report``), from the runs'
    ``metrics.csv``; ``scatter``: also ``campaign_scatter.png``, from every record."""
    campaign = Path(campaign)
    paths = find_campaign_runs(campaign)
    if not paths:
        raise FileNotFoundError(f"{campaign} holds no runs (expected CAMPAIGN/STRATEGY/RUN/)")
    groups = {
        name: [load_run(p, goal_outcomes=False, records=scatter) for p in runs]
        for name, runs in paths.items()
    }
    out_dir = Path(out_dir) if out_dir is not None else campaign / "report"
    with _staged(out_dir) as (tmp, written):
        figures = [campaign_coverage_figure(groups, tmp / "campaign_coverage.png")]
        if scatter:
            figures.append(campaign_scatter_figure(groups, tmp / "campaign_scatter.png"))
        md = _campaign_markdown(campaign, groups, figures, tmp)
        written += figures + _write_summaries(md, tmp)
    return written


def report(path: Path, out_dir: Path | None = None, scatter: bool = False) -> list[Path]:
    """A run's report when ``path`` is a run folder, else a campaign's (``scatter``: the
    campaign's scatter figure too; a run's report always has its own)."""
    if RunStore.is_run(path):
        return report_run(path, out_dir)
    return report_campaign(path, out_dir, scatter)
