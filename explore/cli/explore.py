"""``ergo explore``: run (or resume) an exploration on a rig."""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

from explore.cli.rerun_flags import add_rerun_arguments, check_viewer
from explore.cli.run_paths import existing_run
from explore.rigs.rig import RIGS
from explore.runs.layout import METRICS_FILE
from plumbing.cli_errors import CliError
from robot.bus_flags import add_bus_arguments, bus_flags


def add_rig_arguments(p: argparse.ArgumentParser) -> None:
    """Flags that choose and configure a rig (shared by the commands that drive one)."""
    p.add_argument("--rig", choices=sorted(RIGS), default=None, help="rig (default sim)")
    p.add_argument("--rig-id", default=None, help="physical rig id (finds its calibration)")
    add_bus_arguments(p, exclusive=False)
    p.add_argument("--camera", help="hardware rigs: camera index, path or URL")
    p.add_argument(
        "--rig-option", action="append", default=[], metavar="KEY=JSON",
        help="any other rig option, e.g. render_size=[240,240]",
    )  # fmt: skip


def rig_options(args: argparse.Namespace) -> dict[str, Any]:
    """The rig options the flags give (bus flags, ``--camera``, ``--rig-option``)."""
    opts = bus_flags(args)
    if getattr(args, "camera", None) is not None:
        opts["camera"] = args.camera
    opts.update(parse_key_values(args.rig_option, "--rig-option"))
    return opts


def rig_of(args: argparse.Namespace) -> Any:
    """The ``RigConfig`` the rig flags describe (``--rig``, ``--rig-id``, options)."""
    from explore.rigs.rig import RigConfig

    return RigConfig(args.rig or RigConfig.name, args.rig_id or RigConfig.rig_id, rig_options(args))


def parse_key_values(items: list[str], flag: str) -> dict[str, Any]:
    """``KEY=VALUE`` flags into a dict; VALUE is JSON when it parses, else a plain string."""
    out: dict[str, Any] = {}
    for item in items:
        key, sep, raw = item.partition("=")
        if not sep or not key:
            raise CliError(f"{flag} {item!r}: expected KEY=VALUE")
        try:
            out[key] = json.loads(raw)
        except json.JSONDecodeError:
            out[key] = raw
    return out


def strategies_help() -> str:
    """The strategies and what each is, one line each (the epilog of ``ergo explore --help``)."""
    from explore.learner.strategies import STRATEGIES

    width = max(len(name) for name in STRATEGIES)
    lines = [f"  {name:<{width}}  {entry.summary}" for name, entry in STRATEGIES.items()]
    return "strategies (--strategy NAME):\n" + "\n".join(lines)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "explore",
        help="run an exploration (or resume one) on the twin or a physical arm",
        description="Explore with a strategy; every episode is stored durably in the run folder.",
        epilog=strategies_help(),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add_rig_arguments(p)
    p.add_argument(
        "--strategy", default=None, metavar="NAME",
        help="exploration strategy (default rpe; the strategies are listed below)",
    )  # fmt: skip
    p.add_argument(
        "--strategy-option", action="append", default=[], metavar="KEY=JSON",
        help="strategy option, repeatable (JSON or a string): bootstrap=100, vae=models/vae",
    )  # fmt: skip
    p.add_argument(
        "--preset", default=None, metavar="NAME",
        help="a published campaign's options for the strategy, under --strategy-option: "
        "corl2018 (the ArmBalls campaign, with --rig arm2balls)",
    )  # fmt: skip
    p.add_argument("--episodes", type=int, default=None, help="total episodes (default 300)")
    p.add_argument("--seed", type=int, default=None, help="random seed (default 0)")
    p.add_argument("--out", type=Path, help="new run folder (default runs/STRATEGY-sSEED-TIME)")
    p.add_argument("--resume", type=Path, metavar="RUN", help="continue the run in RUN")
    p.add_argument(
        "--resume-or-new", action="store_true",
        help="with --out: continue the run there if it exists, else start it",
    )  # fmt: skip
    p.add_argument(
        "--allow-changed-inputs", action="store_true",
        help="resume even though the run's calibration files or goal-space model changed "
        "since it started (run.json keeps the old record)",
    )  # fmt: skip
    p.add_argument(
        "--warm-start", type=Path, default=None, metavar="TWIN_RUN",
        help="a run of the same strategy made on the twin (--rig sim, with or without --rig-id) "
        "whose episodes seed this run's learner, kept apart from its own (docs/warm_start.md)",
    )  # fmt: skip
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    add_rerun_arguments(p)
    p.set_defaults(func=run_explore)


def _strategy_options(args: argparse.Namespace, strategy: str) -> dict[str, Any]:
    """The strategy options the flags give: the ``--preset``'s, then ``--strategy-option``."""
    opts: dict[str, Any] = {}
    if args.preset is not None:
        from explore.learner.strategies import StrategyError
        from explore.learner.strategies.registry import preset_options

        try:
            opts.update(preset_options(args.preset, strategy))
        except StrategyError as exc:
            raise CliError(str(exc)) from None
    opts.update(parse_key_values(args.strategy_option, "--strategy-option"))
    return opts


def _new_config(args: argparse.Namespace) -> Any:
    """A new run's ``RunConfig`` from the flags (defaults where none is given), checked: a bad
    value is one ``CliError`` line naming its flag."""
    from explore.runs.config import (
        DEFAULT_EPISODES,
        DEFAULT_SEED,
        RunConfig,
        RunConfigError,
        StrategyConfig,
        flag_of,
    )

    name = args.strategy or StrategyConfig.name
    options = _strategy_options(args, name)
    config = RunConfig(
        rig=rig_of(args),
        strategy=StrategyConfig(name, options),
        seed=DEFAULT_SEED if args.seed is None else args.seed,
        episodes=DEFAULT_EPISODES if args.episodes is None else args.episodes,
        warm_start=None if args.warm_start is None else str(args.warm_start.resolve()),
    )
    try:  # a bad field named by the flag that set it
        config = config.checked(label=flag_of)
    except RunConfigError as exc:
        raise CliError(str(exc)) from None
    _check_model(name, options)
    return config


def _check_model(strategy: str, options: dict[str, Any]) -> None:
    """A strategy that needs a trained model (a VAE, an SAE) and was given none: one line
    naming the flag that gives it and the commands that make one (the entry's ``Model``)."""
    from explore.learner.strategies import STRATEGIES

    entry = STRATEGIES.get(strategy)  # an unknown name is the config check's line
    model = entry.model if entry is not None else None
    if model is not None and not options.get(model.option):
        raise CliError(
            f"--strategy {strategy} needs {model.what}: give --strategy-option "
            f"{model.option}=PATH (make one with: {model.recipe})"
        )


def _refuse_changes(args: argparse.Namespace) -> Any:
    """On resume, the run's own config wins: a check that refuses flags that would change it."""

    def check(config: Any) -> None:
        for flag, value, held in (
            ("--strategy", args.strategy, config.strategy.name),
            ("--seed", args.seed, config.seed),
            ("--rig", args.rig, config.rig.name),
        ):
            if value is not None and value != held:
                raise CliError(
                    f"{flag} {value} differs from the run's {held!r}: a run keeps its config"
                )
        given_prior = getattr(args, "warm_start", None)
        if given_prior is not None and str(given_prior.resolve()) != config.warm_start:
            raise CliError(
                f"--warm-start {given_prior} differs from the run's prior "
                f"({config.warm_start or 'none'}): a run keeps its prior"
            )
        given = _strategy_options(args, config.strategy.name)
        # each option given as the run holds it (a new run's run.json also holds the options
        # whose default changed, written out: runs.config.CHANGED_STRATEGY_DEFAULTS)
        kept = config.strategy.options
        if any(key not in kept or kept[key] != value for key, value in given.items()):
            raise CliError(
                f"--strategy-option {given} differs from the run's {config.strategy.options}: "
                "a run keeps the strategy options it started with"
            )

    return check


def run_explore(args: argparse.Namespace) -> int:
    from explore.learner.strategies import StrategyError
    from explore.rigs.rig import RigError
    from explore.runs.open_run import open_run
    from explore.runs.store import RunStoreError
    from robot.errors import RobotError

    if args.episodes is not None and args.episodes < 1:
        raise CliError(f"--episodes must be at least 1, got {args.episodes}")
    if args.resume and args.out:
        raise CliError("give either --resume RUN or --out DIR, not both")
    if args.resume_or_new and not args.out:
        raise CliError("--resume-or-new needs --out DIR")
    check_viewer(args)  # before any run folder is made
    if args.resume is not None:
        existing_run(args.resume, "--resume")
    try:
        if args.resume is not None:
            run = open_run(
                args.resume, mode="resume", episodes=args.episodes,
                rig_options=rig_options(args),  # ports change between sessions
                check_resumed=_refuse_changes(args),
                allow_changed_inputs=args.allow_changed_inputs,
            )  # fmt: skip
        else:
            config = _new_config(args)  # checked by open_run before anything is made
            out = args.out or Path("runs") / (
                f"{config.strategy.name}-s{config.seed}-{time.strftime('%Y%m%d-%H%M%S')}"
            )
            # --resume-or-new: new or resumed is decided under the run's lock
            run = open_run(
                out, config, mode="auto" if args.resume_or_new else "new",
                episodes=args.episodes, rig_options=rig_options(args),
                check_resumed=_refuse_changes(args),
                allow_changed_inputs=args.allow_changed_inputs,
            )  # fmt: skip
    except (RunStoreError, RigError, StrategyError) as exc:
        raise CliError(str(exc)) from exc
    for line in run.notes():
        print(line, file=sys.stderr)

    from explore.cli.rerun_flags import make_recorder

    store = run.store
    if len(store) >= run.config.episodes:  # nothing to do: no recording, no rig connected
        run.close()
        print(
            f"{store.path}: already {len(store)} episodes (asked for {run.config.episodes}); "
            f"extend it with --episodes N"
        )
        return 0
    bar = _progress_bar(run.config.episodes, len(store), disabled=args.no_progress)
    recorder = make_recorder(
        args, store.path, records=store.records, config=run.config, strategy=run.strategy
    )

    def on_episode(p: Any) -> None:
        if bar:
            bar.update(p)
        if recorder:
            recorder.on_progress(p)

    explorer = run.explorer(on_episode, recorder.on_record if recorder else None)
    new_run = run.created
    closer = _Closer(recorder, run, bar)
    try:
        explorer.run(run.config.episodes)
    except BaseException as exc:
        unsaved = explorer.unsaved + closer.close()
        if new_run and not len(store):
            # a new run that stored nothing (a rig that did not connect): the same command
            # can then run again
            done = _discard(run)
            if isinstance(exc, RobotError | RunStoreError):
                raise CliError(f"{exc}; nothing stored: {done}") from exc
            raise
        unsaved += _coverage_curve(store.path, len(store))
        if isinstance(exc, RobotError | RunStoreError):
            also = f" (not written either: {'; '.join(unsaved)})" if unsaved else ""
            raise CliError(
                f"{exc}; run paused after {len(store)} episodes: resume with "
                f"ergo explore --resume {store.path}{also}"
            ) from exc
        raise
    # the figure first: it needs only metrics.csv, and closing a viewer's stream can take time
    for line in _coverage_curve(store.path, len(store)) + closer.close():
        print(f"not written: {line}", file=sys.stderr)
    if run.warm is not None:
        print(run.warm.summary(), file=sys.stderr)
    last = explorer.metrics.rows[-1] if explorer.metrics.rows else None
    cells = last["ball_cells"] if last else 0
    print(f"{store.path}: {len(store)} episodes, {cells} ball cells reached")
    return 0


def _discard(run: Any) -> str:
    """Remove what a new run that stored nothing created, so that the same command can run
    again; returns what was done, in words."""
    from explore.runs.open_run import discard_empty_run

    try:
        discard_empty_run(run.path)
    except OSError as exc:
        return f"{run.path} could not be removed ({exc})"
    return f"{run.path} removed (the same command can be run again)"


class _Closer:
    """Closes the recorder, the run and the bar, once; a failure to close one (a full disk
    under the recorder's writer) does not keep the others open."""

    def __init__(self, *things: Any) -> None:
        self.things = [t for t in things if t is not None]

    def close(self) -> list[str]:
        """Close them all; returns what failed, in words."""
        things, self.things = self.things, []
        failed = []
        for thing in things:
            try:
                thing.close()
            except Exception as exc:
                failed.append(f"the {type(thing).__name__.strip('_').lower()} ({exc})")
        return failed


def _coverage_curve(run: Path, episodes: int) -> list[str]:
    """Draw ``RUN/coverage.png`` when the run has episodes; returns what failed, in words."""
    from explore.report.figures import coverage_curve

    if not episodes or not (run / METRICS_FILE).exists():
        return []
    try:
        coverage_curve(run)
    except OSError as exc:  # a full disk: the figure is derived, the run is kept
        return [f"coverage.png ({exc.strerror or exc})"]
    return []


def _progress_bar(total: int, initial: int, disabled: bool) -> Any:
    from explore.runs.progress import ProgressBar

    return None if disabled else ProgressBar(total, initial)
