"""A run folder named on the command line that is not there: one line naming the flag and the
nearest folder beside it (``--resume runs/rge-efr-s`` -> ``did you mean 'runs/rge-efr-s0'?``),
before anything is opened. Shared by ``ergo explore --resume``, ``ergo report``, ``ergo
replay``, ``ergo export lerobot`` and ``ergo runs``."""

from __future__ import annotations

from pathlib import Path

from explore.runs.layout import RUN_FILE
from plumbing.cli_errors import CliError
from plumbing.registry import nearest


def near_miss(path: Path, runs_only: bool = True) -> str:
    """`` (did you mean 'PARENT/NAME'?)`` for the folder beside ``path`` whose name is nearest
    to its name (``plumbing.registry.nearest``), among the run folders (a ``run.json``
    inside) or, with ``runs_only`` False, every folder; "" when none is near or the parent is
    not a folder."""
    parent = path.parent
    try:
        beside = [p for p in parent.iterdir() if p.is_dir()]
    except OSError:
        return ""
    if runs_only:
        beside = [p for p in beside if (p / RUN_FILE).is_file()]
    name = nearest(path.name, sorted(p.name for p in beside))
    return "" if name is None else f" (did you mean {str(parent / name)!r}?)"


def existing_run(path: Path, flag: str = "", runs_only: bool = True) -> Path:
    """``path`` when it is a folder; else a ``CliError``: ``FLAG PATH: no such run folder``
    with the nearest one beside it (``near_miss``). ``flag`` "" for a positional argument."""
    if path.is_dir():
        return path
    what = "run folder" if runs_only else "folder"
    named = f"{flag} {path}" if flag else str(path)
    raise CliError(f"{named}: no such {what}{near_miss(path, runs_only)}")
