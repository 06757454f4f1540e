"""``ergo export lerobot RUN [RUN...] --out DIR``: run folders as a LeRobotDataset v3.0."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from plumbing.cli_errors import CliError


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("export", help="export runs for other tools (a LeRobot dataset)")
    kinds = p.add_subparsers(dest="export_command", metavar="FORMAT")
    kinds.required = True
    lerobot = kinds.add_parser(
        "lerobot",
        help="runs as one LeRobotDataset v3.0 (parquet + AV1 video)",
        description="Write the episodes of the runs, in order, as one LeRobotDataset v3.0: a "
        "frame per control tick (joints read, command sent), the DMP parameters, goal, "
        "context and outcome of each episode, and the camera frames of runs made with "
        "--rig-option record_video=SIDE. The runs are only read.",
    )
    lerobot.add_argument("runs", nargs="+", type=Path, metavar="RUN", help="run folders")
    lerobot.add_argument("--out", type=Path, required=True, help="new (or empty) dataset folder")
    lerobot.add_argument(
        "--no-video", action="store_true", help="leave out the camera frames the runs kept"
    )
    lerobot.set_defaults(func=run_export_lerobot)


def run_export_lerobot(args: argparse.Namespace) -> int:
    from plumbing.registry import INSTALL

    try:  # the export extra, checked before any work starts
        import av  # noqa: F401
        import pyarrow  # noqa: F401
    except ModuleNotFoundError as exc:
        hint = INSTALL.get(exc.name or "", "pip install 'ergo-explore[export]'")
        raise CliError(f"ergo export lerobot needs the Python package {exc.name}: {hint}") from None
    from explore.cli.run_paths import existing_run
    from explore.export.episodes import ExportError
    from explore.export.lerobot import export_lerobot
    from explore.runs.store import RunStoreError

    for run in args.runs:
        existing_run(run)
    try:
        summary = export_lerobot(args.runs, args.out, video=not args.no_video)
    except (ExportError, RunStoreError) as exc:
        raise CliError(str(exc)) from exc
    for line in summary.warnings:
        print(f"ergo: warning: {line}", file=sys.stderr)
    if summary.video_side:
        video = f", video {summary.video_side} px"
    elif args.no_video:
        video = ", no video (--no-video)"
    else:
        video = (
            ", no video: the runs kept no camera frames (explore with --rig-option "
            "record_video=128 to keep them; docs/ecosystem.md)"
        )
    print(
        f"{summary.out}: LeRobotDataset v3.0, {summary.episodes} episodes, {summary.frames} "
        f"frames, {len(summary.tasks)} tasks{video}"
    )
    return 0
