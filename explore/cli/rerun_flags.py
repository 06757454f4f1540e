"""The rerun flags of ``ergo explore`` (``--rerun``, ``--rerun-connect``, ``--rerun-stride``) and
the recorder they ask for."""

from __future__ import annotations

import argparse
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from plumbing.cli_errors import CliError

RERUN_MODES = ("save", "spawn", "off")


def add_rerun_arguments(parser: argparse.ArgumentParser) -> None:
    """``--rerun {save,spawn,off}``, ``--rerun-connect URL``, ``--rerun-stride N``."""
    g = parser.add_argument_group("rerun recording")
    g.add_argument(
        "--rerun",
        choices=RERUN_MODES,
        default="save",
        help="save RUN/recording.rrd (default; a resumed run writes recording-2.rrd, ...), "
        "spawn a viewer, or off",
    )
    g.add_argument(
        "--rerun-connect",
        metavar="URL",
        default=None,
        help="stream to a running viewer instead, e.g. rerun+http://127.0.0.1:9876/proxy",
    )
    g.add_argument(
        "--rerun-stride",
        type=int,
        default=1,
        metavar="N",
        help="log the image and joint trajectories every N episodes (default 1)",
    )


def check_viewer(args: argparse.Namespace) -> None:
    """Before anything is made: ``--rerun spawn`` needs a viewer to start and a display for
    it. Without a display, the recording is saved instead (one line says so); without a viewer
    executable, a ``CliError`` in one line (no run folder is made)."""
    if getattr(args, "rerun", "save") != "spawn" or getattr(args, "rerun_connect", None):
        return
    import sys

    from explore.report.recorder import has_display, viewer_executable

    if not has_display():
        print(
            "no display here (DISPLAY and WAYLAND_DISPLAY unset): --rerun spawn would open no "
            "viewer; saving RUN/recording.rrd instead (`ergo replay RUN` where there is one)",
            file=sys.stderr,
        )
        args.rerun = "save"
    elif viewer_executable() is None:
        raise CliError(
            f"--rerun spawn: no rerun viewer beside {sys.executable} nor on PATH (it comes with "
            "pip install rerun-sdk); or --rerun save and `ergo replay RUN` later"
        )


def make_recorder(
    args: argparse.Namespace,
    run_path: Path,
    records: Iterable[Any] | None = None,
    config: Any = None,
    strategy: Any = None,
    load_models: bool = False,
) -> Any:
    """The ``Recorder`` the flags ask for (``explore.report.recorder.open_recorder``), or None
    for ``--rerun off``; a bad ``--rerun-stride`` is a ``CliError``."""
    from explore.report.recorder import open_recorder

    stride = int(getattr(args, "rerun_stride", 1))
    if stride < 1:
        raise CliError(f"--rerun-stride must be at least 1, got {stride}")
    return open_recorder(
        run_path, getattr(args, "rerun", "save"), getattr(args, "rerun_connect", None), stride,
        records=records, config=config, strategy=strategy, load_models=load_models,
    )  # fmt: skip
