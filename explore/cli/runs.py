"""``ergo runs check RUN`` and ``ergo runs salvage RUN``: what a run folder's history holds, and
keeping every good record of a damaged one so that the run can resume
(``explore/runs/repair.py``); ``ergo runs fingerprint RUN [RUN ...]``: what each run explored,
as one SHA-256 (``explore/runs/fingerprint.py``)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from plumbing.cli_errors import CliError


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "runs",
        help="check a run folder's history, or salvage a damaged one",
        description="Check or salvage a run folder (nothing is ever deleted).",
    )
    cmds = p.add_subparsers(dest="runs_command", metavar="ACTION")
    cmds.required = True
    check = cmds.add_parser(
        "check",
        help="say what the history holds: good records, damage, missing episodes, camera "
        "frames, whether run.json can be run (exit 1 if it cannot be resumed as it is)",
    )
    check.add_argument("run", type=Path, metavar="RUN")
    check.set_defaults(func=run_check)
    salvage = cmds.add_parser(
        "salvage",
        help="keep the history's good records in order, move the rest to RUN/salvage/N/, and "
        "let the run resume",
    )
    salvage.add_argument("run", type=Path, metavar="RUN")
    salvage.set_defaults(func=run_salvage)
    fingerprint = cmds.add_parser(
        "fingerprint",
        help="one SHA-256 over what each run explored (parameters, outcomes, metrics; no "
        "times), computed from its history: equal for the same run (exit 1 if the runs "
        "given differ)",
    )
    fingerprint.add_argument("runs", type=Path, nargs="+", metavar="RUN")
    fingerprint.set_defaults(func=run_fingerprint)


def run_check(args: argparse.Namespace) -> int:
    from explore.cli.run_paths import existing_run
    from explore.runs.lock import describe_holder, holder_of
    from explore.runs.repair import describe, survey
    from explore.runs.store import RunStoreError

    existing_run(args.run)
    try:
        s = survey(args.run)
        holder = holder_of(args.run)  # a writer.lock that is not a plain file: RunStoreError
    except RunStoreError as exc:
        raise CliError(str(exc)) from exc
    print(f"{args.run}:")
    if holder is not None:
        print(f"being written now by {describe_holder(holder)}")
    for line in describe(args.run, s):
        print(f"  {line}")
    return 0 if s.resumable else 1


def run_salvage(args: argparse.Namespace) -> int:
    from explore.cli.run_paths import existing_run
    from explore.runs.repair import salvage
    from explore.runs.store import RunStoreError

    existing_run(args.run)

    try:
        r = salvage(args.run)
    except RunStoreError as exc:
        raise CliError(str(exc)) from exc
    if r.folder is None:
        print(f"{args.run}: nothing to salvage: {r.kept} episode(s), all in order", file=sys.stderr)
        return 0
    print(
        f"{args.run}: kept episodes 0..{r.kept - 1} ({r.kept}) as the history; moved "
        f"{r.beyond} good record(s) that did not follow on and {r.damaged_bytes} damaged "
        f"byte(s) to {r.folder}; resume with: ergo explore --resume {args.run}"
        if r.kept
        else f"{args.run}: no episode could be kept in order; moved {r.beyond} good record(s) "
        f"and {r.damaged_bytes} damaged byte(s) to {r.folder}; start again with: ergo explore "
        f"--resume {args.run}"
    )
    return 0


def run_fingerprint(args: argparse.Namespace) -> int:
    from explore.rigs.rig import RigError
    from explore.runs.fingerprint import fingerprint_run
    from explore.runs.store import RunStoreError

    digests = set()
    for run in args.runs:
        try:
            found = fingerprint_run(run)
        except (RunStoreError, RigError) as exc:
            raise CliError(str(exc)) from exc
        fp = found.fingerprint
        digests.add(fp.hexdigest())
        line = f"{fp.hexdigest()}  {run}: {fp.episodes} episodes, {fp.ball_cells} ball cells"
        if found.torn_bytes:
            line += f" (a torn last record of {found.torn_bytes} bytes left out)"
        old = found.recorded
        if old and old.get("episodes") == fp.episodes and old.get("sha256") != fp.hexdigest():
            line += (
                f"; run.json recorded {str(old.get('sha256'))[:16]}... for as many episodes "
                "(another version's arithmetic)"
            )
        print(line)
    if len(args.runs) > 1:
        same = len(digests) == 1
        print("the same run" if same else f"{len(digests)} different runs")
        return 0 if same else 1
    return 0
