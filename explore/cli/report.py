"""``ergo report`` (figures and a summary of a run or a campaign) and ``ergo replay`` (open a
run's rerun recording). Heavy imports (matplotlib, rerun) happen inside the commands."""

from __future__ import annotations

import argparse
import shlex
import subprocess
import sys
from pathlib import Path

from plumbing.cli_errors import CliError


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "report",
        help="figures and a one-page summary (Markdown, HTML) of a run or a campaign",
        description="Write PNG figures (960x640 px) and summary.md / summary.html for a run "
        "folder, or for a campaign folder CAMPAIGN/STRATEGY/RUN/ (mean and spread over seeds, "
        "from the runs' metrics.csv: seconds).",
    )
    p.add_argument("path", type=Path, metavar="RUN|CAMPAIGN")
    p.add_argument("--out", type=Path, help="output folder (default PATH/report)")
    p.add_argument(
        "--scatter",
        action="store_true",
        help="campaigns: also campaign_scatter.png, every episode's positions (reads every "
        "record: minutes for 100k episodes)",
    )
    p.set_defaults(func=run_report)

    p = sub.add_parser(
        "replay",
        help="open a run's rerun recording in the viewer (or print the command to do so)",
        description="Open RUN's recording (recording.rrd, recording-2.rrd, ... of a resumed run) "
        "in the rerun viewer. Without a display, print the command to run elsewhere. A run "
        "explored with --rerun off gets a recording written from its history first.",
    )
    p.add_argument("run", type=Path, metavar="RUN")
    p.add_argument(
        "--print", action="store_true", dest="print_only", help="only print the viewer command"
    )
    p.add_argument(
        "--rerun-stride",
        type=int,
        default=1,
        metavar="N",
        help="when writing a recording from the history: images every N episodes",
    )
    p.set_defaults(func=run_replay)


def run_report(args: argparse.Namespace) -> int:
    from explore.cli.run_paths import existing_run
    from explore.report.summary import report
    from explore.runs.store import RunStore, RunStoreError

    existing_run(args.path, runs_only=False)  # a run or a campaign
    try:
        written = report(args.path, args.out, args.scatter)
    except RunStoreError as exc:
        raise CliError(str(exc)) from exc
    for p in written:
        print(p)
    from explore.report.reality_gap import gap_line
    from explore.report.run_data import run_scene

    if RunStore.is_run(args.path):  # a run warmed by a prior: its reality gap in one line
        line = gap_line(args.path, run_scene(RunStore.read_meta(args.path)["config"]).unit)
        if line is not None:
            print(f"reality gap: {line}")
    return 0


def viewer_command(files: list[Path]) -> list[str]:
    """The ``rerun`` viewer command for ``files`` (this environment's executable if any)."""
    from explore.report.recorder import viewer_executable

    return [viewer_executable() or "rerun", *(str(f.resolve()) for f in files)]


def run_replay(args: argparse.Namespace) -> int:
    from explore.cli.rerun_flags import make_recorder
    from explore.cli.run_paths import existing_run
    from explore.report.recorder import has_display, recording_paths
    from explore.runs.store import RunStore, RunStoreError

    existing_run(args.run)
    if not RunStore.is_run(args.run):
        raise CliError(f"{args.run} is not a run folder (no run.json)")
    files = recording_paths(args.run)
    if not files:
        from explore.runs.store import iter_history

        print(f"{args.run} has no recording: writing one from its history", file=sys.stderr)
        ns = argparse.Namespace(rerun="save", rerun_connect=None, rerun_stride=args.rerun_stride)
        try:
            # a learned goal space's model is loaded too: goal/reached for those runs as well
            recorder = make_recorder(ns, args.run, records=[], load_models=True)
        except RunStoreError as exc:
            raise CliError(str(exc)) from exc
        assert recorder is not None
        with recorder:
            for rec in iter_history(args.run):
                recorder.on_record(rec)
        files = recording_paths(args.run)
    cmd = viewer_command(files)
    if args.print_only or not has_display():
        if not args.print_only:
            print("no display here; open the recording on a machine with one:", file=sys.stderr)
        print(shlex.join(["rerun", *cmd[1:]]))
        return 0
    subprocess.Popen(cmd, start_new_session=True)  # the viewer outlives this command
    print(f"opened {' '.join(str(f) for f in files)} in the rerun viewer", file=sys.stderr)
    return 0
