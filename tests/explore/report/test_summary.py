"""``ergo report``: figures of the documented size and the summaries, for a run and a campaign."""

from __future__ import annotations

import dataclasses
import os
import shutil
import struct
from pathlib import Path

import numpy as np
import pytest

from explore.cli import main
from explore.report.figures import FIG_PX, goal_panels, goals_figure
from explore.report.run_data import load_run
from explore.report.summary import markdown_to_html

N = 10


def png_size(path: Path) -> tuple[int, int]:
    """(width, height) from a PNG's IHDR chunk."""
    head = path.read_bytes()[:24]
    assert head[:8] == b"\x89PNG\r\n\x1a\n", f"{path} is not a PNG"
    return struct.unpack(">II", head[16:24])


def explore(out: Path, seed: int) -> Path:
    args = ["explore", "--episodes", str(N), "--seed", str(seed), "--out", str(out)]
    assert main([*args, "--no-progress"]) == 0
    return out


@pytest.fixture(scope="module")
def runs(tmp_path_factory) -> list[Path]:
    base = tmp_path_factory.mktemp("runs")
    return [explore(base / f"seed-{s}", s) for s in (0, 1)]


def test_report_of_a_run_writes_figures_and_summaries(runs, tmp_path, capsys):
    out = tmp_path / "report"
    assert main(["report", str(runs[0]), "--out", str(out)]) == 0
    printed = capsys.readouterr().out.split()
    for name in ("coverage.png", "scatter.png"):
        path = out / name
        assert str(path) in printed
        assert png_size(path) == FIG_PX
        assert path.stat().st_size > 10_000  # something drawn, not a blank canvas
    assert not (out / "goals.png").exists()  # RPE sets no goals
    md = (out / "summary.md").read_text()
    assert "ball cells reached" in md and f"| episodes | {N} (planned {N}) |" in md
    assert "episodes that moved the ball" in md and "![coverage](coverage.png)" in md
    page = (out / "summary.html").read_text()
    assert page.count("data:image/png;base64,") == 2 and "<table>" in page


def test_summary_after_a_resume_says_the_new_plan(tmp_path):
    run = tmp_path / "run"
    args = ["explore", "--seed", "3", "--out", str(run), "--resume-or-new", "--no-progress"]
    assert main([*args, "--episodes", "3", "--rerun", "off"]) == 0
    assert main([*args, "--episodes", "5", "--rerun", "off"]) == 0
    assert main(["report", str(run)]) == 0
    assert "| episodes | 5 (planned 5) |" in (run / "report" / "summary.md").read_text()
    assert main([*args, "--rerun", "off"]) == 0  # no count asked: the last plan stays
    assert main(["report", str(run)]) == 0
    assert "| episodes | 5 (planned 5) |" in (run / "report" / "summary.md").read_text()


def test_report_default_folder_is_inside_the_run(runs):
    assert main(["report", str(runs[1])]) == 0
    assert (runs[1] / "report" / "summary.html").is_file()


def test_campaign_report_has_mean_and_spread(runs, tmp_path):
    campaign = tmp_path / "campaign"
    for strategy in ("rpe", "rpe-copy"):
        for run in runs:
            shutil.copytree(
                run, campaign / strategy / run.name, ignore=shutil.ignore_patterns("report")
            )
    out = tmp_path / "creport"
    assert main(["report", str(campaign), "--out", str(out), "--scatter"]) == 0
    for name in ("campaign_coverage.png", "campaign_scatter.png"):
        assert png_size(out / name) == FIG_PX
        assert (out / name).stat().st_size > 10_000
    md = (out / "summary.md").read_text()
    assert "--scatter" not in md
    assert "| rpe | 2 |" in md and "| rpe-copy | 2 |" in md
    assert "+-" in md  # mean +- std over seeds
    row = md.split("| rpe-copy |")[1].splitlines()[0]
    cells = md.split("| rpe |")[1].split("|")[2]  # the same runs: Welch p 1, or none if no spread
    assert row.rstrip().endswith("| 1 |") or ("+- 0.0" in cells and row.endswith("|  |"))


def test_report_refuses_a_folder_without_runs(tmp_path):
    assert main(["report", str(tmp_path)]) == 2


def test_goals_figure_when_goals_exist(runs, tmp_path):
    run = load_run(runs[0])
    rng = np.random.default_rng(0)
    run = dataclasses.replace(run, goals=rng.normal(size=(run.n, 4)))
    run.reached = run.goals + 0.1
    path = goals_figure(run, tmp_path / "goals.png")
    assert path is not None and png_size(path) == FIG_PX


def test_goal_panels_follow_the_modules(runs):
    """Two modules (3 and 2 coordinates, NaN-padded to 3): pairs of each module's own goal."""
    run = load_run(runs[0])
    goals = np.full((run.n, 3), np.nan)
    module = np.full(run.n, -1)
    goals[2:6] = 0.5
    module[2:6] = 0
    goals[6:, :2] = -0.5
    module[6:] = 1
    run = dataclasses.replace(run, goals=goals, module=module)
    assert goal_panels(run) == [(0, 0, 1), (0, 2, 2), (1, 0, 1)]


def test_report_of_a_goal_run_has_the_reached_outcomes(goal_run, tmp_path):
    from explore.learner.goal_spaces import wrap_safe_features
    from explore.rigs.arena import TWIN_ARENA

    run = load_run(goal_run)
    assert run.goals.shape == (7, 3) and run.reached is not None
    with_goal = np.all(np.isfinite(run.goals), axis=1)
    assert with_goal.sum() == 4 and not np.isfinite(run.reached[~with_goal]).any()
    seen = with_goal & np.all(np.isfinite(run.ball), axis=1)
    np.testing.assert_allclose(
        run.reached[seen], wrap_safe_features(run.ball[seen], TWIN_ARENA.ring)
    )
    out = tmp_path / "report"
    assert main(["report", str(goal_run), "--out", str(out)]) == 0
    assert png_size(out / "goals.png") == FIG_PX


def test_markdown_to_html_escapes_and_embeds(tmp_path):
    (tmp_path / "a.png").write_bytes(b"\x89PNG fake")
    page = markdown_to_html(
        "# T <x>\n\n| a | b |\n|---|---|\n| 1 | `c` |\n\n![a](a.png)\n", tmp_path
    )
    assert "<h1>T &lt;x&gt;</h1>" in page and "<code>c</code>" in page
    assert "data:image/png;base64," in page


def _campaign(runs: list[Path], root: Path) -> Path:
    campaign = root / "campaign"
    for run in runs:
        shutil.copytree(run, campaign / "rpe" / run.name, ignore=shutil.ignore_patterns("report"))
    return campaign


def _table(md: str) -> str:
    return md.split("## Results")[1].split("## Figures")[0]


def test_a_campaign_summary_comes_from_metrics_csv_alone(runs, tmp_path, monkeypatch):
    campaign = _campaign(runs, tmp_path)
    full = tmp_path / "full"
    assert main(["report", str(campaign), "--out", str(full), "--scatter"]) == 0

    import explore.report.run_data as run_data

    def no_records(path):
        raise AssertionError(f"{path}: a record was read")

    monkeypatch.setattr(run_data, "iter_history", no_records)
    out = tmp_path / "fast"
    assert main(["report", str(campaign), "--out", str(out)]) == 0
    assert png_size(out / "campaign_coverage.png") == FIG_PX
    assert not (out / "campaign_scatter.png").exists()
    md = (out / "summary.md").read_text()
    assert f"ergo report {campaign} --scatter" in md  # says what needs the records
    assert _table(md) == _table((full / "summary.md").read_text())  # metrics.csv = history


def test_a_report_stopped_midway_leaves_the_old_one_or_a_marker(runs, tmp_path, monkeypatch):
    import explore.report.summary as summary

    campaign = _campaign(runs, tmp_path)
    out = tmp_path / "report"
    assert main(["report", str(campaign), "--out", str(out)]) == 0
    before = {p.name: p.read_bytes() for p in out.iterdir()}

    def stopped(*args, **kwargs):
        raise KeyboardInterrupt  # Ctrl-C while drawing

    monkeypatch.setattr(summary, "campaign_coverage_figure", stopped)
    with pytest.raises(KeyboardInterrupt):
        summary.report_campaign(campaign, out)
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before  # the old report, whole
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []
    monkeypatch.undo()

    moved, real_replace = [], os.replace

    def replace_once(src, dst):
        if moved:
            raise KeyboardInterrupt  # stopped while moving the new files in
        moved.append(dst)
        real_replace(src, dst)

    monkeypatch.setattr(summary.os, "replace", replace_once)
    with pytest.raises(KeyboardInterrupt):
        summary.report_campaign(campaign, out)
    assert len(moved) == 1 and "run it again" in (out / summary.INCOMPLETE).read_text()
    monkeypatch.undo()
    assert main(["report", str(campaign), "--out", str(out)]) == 0
    assert not (out / summary.INCOMPLETE).exists()
