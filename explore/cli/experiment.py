"""``ergo experiment`` (campaigns of runs) and ``ergo dataset outcomes``.

A campaign is a folder ``CAMPAIGN/STRATEGY/seed-S`` of ordinary run folders
(explore/runs/store.py), one per (strategy, seed), each run by the usual ``Explorer`` as a
trial (explore/campaigns/trial.py), on this machine's processes (``--backend local``) or as Ray
tasks (``--backend ray``). It is resumable: finished runs are skipped, unfinished ones resumed.
At the end the final number of ball cells per strategy (mean +- std over seeds) is printed and
written to ``CAMPAIGN/summary.csv`` with a Welch t-test against RPE, and ``CAMPAIGN/report``
gets the coverage curves (mean and spread over seeds), the scatter plots of end-effector and
ball positions per strategy, and summary.md / summary.html (``--no-report`` skips it).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from explore.campaigns.backends import BACKENDS, DEFAULT_RETRIES
from explore.campaigns.trial import CampaignError
from explore.cli.explore import add_rig_arguments, parse_key_values, rig_of
from explore.learner.presets import PRESETS
from explore.learner.strategies.registry import MODELS
from plumbing.cli_errors import CliError

# Rigs that can render an outcome database (``--rig``): the twin (explore/rigs/sim_dataset.py)
# and those whose rig module has an ``outcome_dataset`` (explore/rigs/armballs.py).
DATASET_RIGS = ("sim", "armballs", "arm2balls")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "experiment",
        help="run a campaign of strategies x seeds (twin or rig, local or Ray) and tabulate cells",
        description="Each (strategy, seed) is a run folder CAMPAIGN/STRATEGY/seed-S; finished "
        "runs are skipped and unfinished ones resumed.",
    )
    p.add_argument("--strategies", required=True, help="comma-separated, e.g. rpe,rge-efr")
    p.add_argument(
        "--seeds", default="1",
        help="a count N (seeds 0..N-1, e.g. 8), a list (0,2,5) or a range (3-7); one seed S "
        "alone: S-S (default 1: seed 0)",
    )  # fmt: skip
    p.add_argument("--episodes", type=int, required=True, help="episodes per run")
    p.add_argument("--out", type=Path, required=True, help="campaign folder")
    p.add_argument(
        "--jobs", "--workers", type=int, default=None,
        help="local: runs in parallel (processes, default 1); ray: CPUs of the Ray instance "
        "started for the campaign (default all; a cluster joined with --ray-address has its own)",
    )  # fmt: skip
    p.add_argument(
        "--backend", choices=sorted(BACKENDS), default="local",
        help="local processes (default) or Ray tasks (pip install 'ergo-explore[ray]')",
    )  # fmt: skip
    p.add_argument(
        "--ray-address", metavar="ADDR",
        help="ray: join this cluster (HOST:PORT of its head, or auto); default: start Ray on "
        "127.0.0.1 for this campaign",
    )  # fmt: skip
    p.add_argument(
        "--retries", type=int, default=DEFAULT_RETRIES,
        help="ray: restarts of a trial whose worker or node died; it resumes (default 2)",
    )  # fmt: skip
    for model in MODELS:
        p.add_argument(
            f"--{model.flag}", type=Path, help=f"{model.what} for the *-{model.flag} strategies"
        )
    p.add_argument(
        "--option", action="append", default=[], metavar="KEY=JSON",
        help="strategy option for every goal-exploration run, e.g. bootstrap=100, or for one "
        "strategy: STRATEGY:KEY=JSON, e.g. 'rge-vae:latents=\"zscore\"'",
    )  # fmt: skip
    p.add_argument(
        "--preset", choices=PRESETS, default=None,
        help="a published campaign's strategy settings, under --option: corl2018 (the "
        "ArmBalls campaign, with --rig arm2balls; docs/results_armballs.md)",
    )  # fmt: skip
    p.add_argument("--no-progress", action="store_true", help="no progress bars")
    p.add_argument(
        "--warm-start", type=Path, default=None, metavar="TWIN_RUN",
        help="a twin run (every trial warmed by it) or a twin campaign (each trial by its "
        "STRATEGY/seed-S run) whose episodes seed the trials' learners (docs/warm_start.md)",
    )  # fmt: skip
    p.add_argument(
        "--no-report", action="store_true",
        help="skip CAMPAIGN/report (coverage curves, summary.md with the Welch test, from the "
        "runs' metrics.csv: seconds), written at the end by default; `ergo report CAMPAIGN "
        "[--scatter]` writes it any time",
    )  # fmt: skip
    add_rig_arguments(p)
    p.set_defaults(func=run_experiment)

    d = sub.add_parser("dataset", help="outcome datasets: rendered on a simulated rig, or a run's")
    dsub = d.add_subparsers(dest="dataset_command", metavar="COMMAND")
    dsub.required = True
    o = dsub.add_parser(
        "outcomes", help="render scenes as episodes see them (representation training data)",
        description="The twin (--rig sim, the default): the ball placed over its ring; "
        "ArmBalls (--rig armballs or arm2balls): the ball, and the distractor, uniform over "
        "the square [-1, 1]^2, as in the CoRL 2018 campaign's database. --run RUN: the "
        "outcome images a run recorded, on any rig (a physical arm's camera view, say); the "
        "run is read, never changed.",
    )  # fmt: skip
    o.add_argument(
        "--rig", choices=DATASET_RIGS, default="sim",
        help="the simulated rig whose scenes to render (default sim: the twin)",
    )  # fmt: skip
    o.add_argument(
        "--n", type=int, default=None,
        help="number of scenes (default 10000); with --run, its first N episodes (default all)",
    )  # fmt: skip
    o.add_argument(
        "--run", type=Path, default=None, metavar="RUN",
        help="the outcome images of this run's episodes instead of rendered scenes",
    )  # fmt: skip
    o.add_argument("--out", type=Path, required=True, help="output .npz")
    o.add_argument("--seed", type=int, default=0, help="random seed")
    o.add_argument(
        "--arm", choices=("rest", "random"), default="rest",
        help="arm at rest (default: as in an episode's outcome image) or in random poses",
    )  # fmt: skip
    o.add_argument(
        "--distractor", action="store_true",
        help="the scene with the distractor (rig option distractor=walk), placed over the ring",
    )  # fmt: skip
    o.add_argument("--no-progress", action="store_true", help="no progress bar")
    o.set_defaults(func=run_dataset_outcomes)


# ---- campaigns ------------------------------------------------------------------------------
def _csv_list(text: str, what: str) -> list[str]:
    items = [s.strip() for s in text.split(",") if s.strip()]
    if not items:
        raise CliError(f"--{what}: give at least one value")
    return items


def parse_seeds(text: str) -> list[int]:
    """``--seeds`` (``vision.cli.parse_seeds``: a count, a list or ranges); a bad one is a
    ``CliError``."""
    from vision.cli import parse_seeds as parse

    try:
        return parse(text)
    except ValueError as exc:
        raise CliError(str(exc)) from None


def run_experiment(args: argparse.Namespace) -> int:
    if args.episodes < 1:
        raise CliError(f"--episodes must be at least 1, got {args.episodes}")
    if args.jobs is not None and args.jobs < 1:
        raise CliError(f"--jobs must be at least 1, got {args.jobs}")
    if args.retries < 0:
        raise CliError(f"--retries must be at least 0, got {args.retries}")
    strategies = _csv_list(args.strategies, "strategies")
    seeds = parse_seeds(args.seeds)
    rig = rig_of(args).to_dict()
    from explore.campaigns.plan import run_campaign
    from explore.campaigns.stats import format_table

    try:
        rows = run_campaign(
            args.out, strategies, seeds, args.episodes, args.jobs,
            {model.flag: getattr(args, model.flag) for model in MODELS},
            parse_key_values(args.option, "--option"), progress=not args.no_progress,
            backend=args.backend, ray_address=args.ray_address, rig=rig, retries=args.retries,
            preset=args.preset, warm_start=args.warm_start,
        )  # fmt: skip
    except CampaignError as exc:
        raise CliError(str(exc)) from exc
    print(format_table(rows))
    print(f"summary: {args.out / 'summary.csv'}")
    if not args.no_report:
        from explore.report.summary import report_campaign
        from explore.runs.store import RunStoreError

        try:
            written = report_campaign(args.out)
        except (OSError, RunStoreError, ValueError) as exc:  # the runs are safe either way
            print(f"report not written ({exc}); try `ergo report {args.out}`")
        else:
            print(f"report: {written[-2]} (figures beside it)")
    return 0


# ---- dataset ---------------------------------------------------------------------------------
def run_dataset_outcomes(args: argparse.Namespace) -> int:
    from explore.rigs.sim_dataset import make_outcome_dataset, save_dataset

    if args.n is not None and args.n < 1:
        raise CliError(f"--n must be at least 1, got {args.n}")
    if args.out.suffix != ".npz":
        raise CliError(f"--out {args.out}: expected a .npz file name")
    if args.run is not None:
        import numpy as np

        from explore.runs.outcome_dataset import run_outcome_dataset
        from explore.runs.store import RunStoreError

        rendering = [
            flag for flag, given in (
                ("--rig", args.rig != "sim"), ("--arm random", args.arm != "rest"),
                ("--distractor", args.distractor), ("--seed", args.seed != 0),
            ) if given
        ]  # fmt: skip
        if rendering:
            raise CliError(f"{', '.join(rendering)}: render scenes; --run takes a run's images")
        try:
            data = run_outcome_dataset(args.run, args.n)
        except RunStoreError as exc:
            raise CliError(str(exc)) from None
        save_dataset(args.out, data)
        seen = int(np.isfinite(data["ball"]).all(axis=1).sum())
        print(
            f"{args.out}: {len(data['images'])} images {data['images'].shape[1:]} from "
            f"{args.run} (ball tracked in {seen})"
        )
        return 0
    args.n = 10000 if args.n is None else args.n
    if args.rig != "sim":
        twin_only = [
            flag for flag, given in (
                ("--arm random", args.arm != "rest"), ("--distractor", args.distractor),
            ) if given
        ]  # fmt: skip
        if twin_only:
            raise CliError(f"{', '.join(twin_only)}: the twin's (--rig sim) only")
        from explore.rigs.rig import RIGS, RigConfig, rig_options

        config = RigConfig(args.rig)
        data = RIGS.load(args.rig).outcome_dataset(
            config, rig_options(config), args.n, seed=args.seed, progress=not args.no_progress
        )
    else:
        data = make_outcome_dataset(
            args.n, seed=args.seed, progress=not args.no_progress, arm=args.arm,
            distractor=args.distractor,
        )  # fmt: skip
    save_dataset(args.out, data)
    what = "ball and distractor" if "distractor" in data else "ball"
    print(f"{args.out}: {args.n} images {data['images'].shape[1:]} with {what} positions")
    return 0
