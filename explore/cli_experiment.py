"""``ergo experiment`` (campaigns of runs), ``ergo vae train``, ``ergo sae train`` and ``ergo
dataset outcomes``.

A campaign is a folder ``CAMPAIGN/STRATEGY/seed-S`` of ordinary run folders (explore/store.py),
one per (strategy, seed), each run by the usual ``Explorer`` as a trial (explore/campaign.py),
on this machine's processes (``--backend local``) or as Ray tasks (``--backend ray``,
explore/campaign_ray.py). It is resumable: finished runs are skipped, unfinished ones resumed.
At the end the final number of ball cells per strategy (mean +- std over seeds) is printed and
written to ``CAMPAIGN/summary.csv`` with a Welch t-test against RPE, and ``CAMPAIGN/report``
gets the coverage curves (mean and spread over seeds), the scatter plots of end-effector and
ball positions per strategy, and summary.md / summary.html (``--no-report`` skips it).
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

from explore.campaign import (  # re-exported: bench/ and tests import them from here
    BACKENDS,
    DEFAULT_RETRIES,
    CampaignError,
    format_table,
    run_campaign,
    run_one,
    strategy_options,
    write_summary,
)
from explore.cli import CliError
from explore.cli_explore import add_rig_arguments, parse_key_values, rig_options
from sim import RENDER_QUALITIES

__all__ = ["format_table", "run_campaign", "run_one", "strategy_options", "write_summary"]


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
    p.add_argument("--vae", type=Path, help="VAE model for the *-vae strategies")
    p.add_argument("--betavae", type=Path, help="beta-VAE model for the *-betavae strategies")
    p.add_argument("--sae", type=Path, help="spatial autoencoder for the *-sae strategies")
    p.add_argument(
        "--option", action="append", default=[], metavar="KEY=JSON",
        help="strategy option for every goal-exploration run, e.g. bootstrap=100, or for one "
        "strategy: STRATEGY:KEY=JSON, e.g. 'rge-vae:latents=\"zscore\"'",
    )  # fmt: skip
    p.add_argument("--no-progress", action="store_true", help="no progress bars")
    p.add_argument(
        "--no-report", action="store_true",
        help="skip CAMPAIGN/report (coverage curves, scatter plots, summary.md with the Welch "
        "test), written at the end by default; `ergo report CAMPAIGN` writes it any time",
    )  # fmt: skip
    add_rig_arguments(p)
    p.set_defaults(func=run_experiment)

    v = sub.add_parser("vae", help="representation learning (VAE)")
    vsub = v.add_subparsers(dest="vae_command", metavar="COMMAND")
    vsub.required = True
    t = vsub.add_parser(
        "train", help="train a VAE on an outcome database", description="Resumable: rerun the "
        "same command to continue from the last checkpoint in --out.",
    )  # fmt: skip
    t.add_argument("--data", type=Path, required=True, help="dataset .npz (ergo dataset outcomes)")
    t.add_argument("--out", type=Path, required=True, help="model folder")
    t.add_argument("--iterations", type=int, default=None, help="total iterations (default 3000)")
    t.add_argument("--beta", type=float, default=None, help="KL weight (default 1: plain VAE)")
    t.add_argument("--capacity", type=float, default=None, help="final KL capacity C, nats")
    t.add_argument(
        "--capacity-iterations", type=int, default=None, metavar="N",
        help="iterations over which C rises from 0 (default 2000; docs/results.md: 500)",
    )  # fmt: skip
    t.add_argument("--lr", type=float, default=None, help="Adam learning rate (default 1e-3)")
    t.add_argument("--batch", type=int, default=None, help="batch size (default 64)")
    add_training_arguments(t)
    t.set_defaults(func=run_vae_train)

    a = sub.add_parser("sae", help="representation learning (spatial autoencoder)")
    asub = a.add_subparsers(dest="sae_command", metavar="COMMAND")
    asub.required = True
    t = asub.add_parser(
        "train", help="train a spatial autoencoder on an outcome database",
        description="Resumable: rerun the same command to continue from the last checkpoint.",
    )  # fmt: skip
    t.add_argument("--data", type=Path, required=True, help="dataset .npz (ergo dataset outcomes)")
    t.add_argument("--out", type=Path, required=True, help="model folder")
    t.add_argument("--iterations", type=int, default=None, help="total iterations (default 700)")
    t.add_argument("--features", type=int, default=8, help="feature maps (default 8)")
    add_training_arguments(t)
    t.set_defaults(func=run_sae_train)

    d = sub.add_parser("dataset", help="datasets rendered on the twin")
    dsub = d.add_subparsers(dest="dataset_command", metavar="COMMAND")
    dsub.required = True
    o = dsub.add_parser(
        "outcomes", help="render ball-on-ring scenes as episodes see them (VAE training data)"
    )
    o.add_argument("--n", type=int, default=10000, help="number of scenes (default 10000)")
    o.add_argument("--out", type=Path, required=True, help="output .npz")
    o.add_argument("--seed", type=int, default=0, help="random seed")
    o.add_argument(
        "--arm", choices=("rest", "random"), default="rest",
        help="arm at rest (default: as in an episode's outcome image) or in random poses",
    )  # fmt: skip
    o.add_argument(
        "--render-quality", choices=RENDER_QUALITIES, default="chosen",
        help="the twin's render settings (default chosen; legacy: the images before 2026-12-01)",
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
    """``--seeds``: "8" -> [0..7] (a count, as in ``--seeds 8``), "0,2,5" -> [0, 2, 5],
    "3-7" -> [3..7], "4-4" -> [4]; lists may mix both ("0,3-5"). Raises CliError."""
    text = text.strip()
    if "," not in text and "-" not in text:
        try:
            count = int(text)
        except ValueError:
            raise CliError(f"--seeds {text!r}: give a count, a list or a range") from None
        if count < 1:
            raise CliError(f"--seeds {count}: a count must be at least 1 (one seed S: S-S)")
        return list(range(count))
    seeds: list[int] = []
    for item in _csv_list(text, "seeds"):
        try:
            if "-" in item:
                lo, hi = (int(v) for v in item.split("-"))
                if hi < lo:
                    raise CliError(f"--seeds {item}: an empty range")
                seeds.extend(range(lo, hi + 1))
            else:
                seeds.append(int(item))
        except ValueError:  # also a negative seed: "-1" splits into "" and "1"
            raise CliError(f"--seeds {item!r}: not a seed or a range of seeds") from None
    return list(dict.fromkeys(seeds))  # each seed once, in the order given


def run_experiment(args: argparse.Namespace) -> int:
    if args.episodes < 1:
        raise CliError(f"--episodes must be at least 1, got {args.episodes}")
    if args.jobs is not None and args.jobs < 1:
        raise CliError(f"--jobs must be at least 1, got {args.jobs}")
    if args.retries < 0:
        raise CliError(f"--retries must be at least 0, got {args.retries}")
    strategies = _csv_list(args.strategies, "strategies")
    seeds = parse_seeds(args.seeds)
    rig = {"name": args.rig or "sim", "rig_id": args.rig_id or "twin",
           "options": rig_options(args)}  # fmt: skip
    try:
        rows = run_campaign(
            args.out, strategies, seeds, args.episodes, args.jobs,
            {"vae": args.vae, "betavae": args.betavae, "sae": args.sae},
            parse_key_values(args.option, "--option"), progress=not args.no_progress,
            backend=args.backend, ray_address=args.ray_address, rig=rig, retries=args.retries,
        )  # fmt: skip
    except CampaignError as exc:
        raise CliError(str(exc)) from exc
    print(format_table(rows))
    print(f"summary: {args.out / 'summary.csv'}")
    if not args.no_report:
        from explore.report import report_campaign
        from explore.store import RunStoreError

        try:
            written = report_campaign(args.out)
        except (OSError, RunStoreError, ValueError) as exc:  # the runs are safe either way
            print(f"report not written ({exc}); try `ergo report {args.out}`")
        else:
            print(f"report: {written[-2]} (figures beside it)")
    return 0


# ---- representation and dataset -------------------------------------------------------------
def add_training_arguments(t: argparse.ArgumentParser) -> None:
    """Seeds, device and progress of a representation's training."""
    t.add_argument("--seed", type=int, default=0, help="random seed")
    t.add_argument(
        "--seeds", default=None, metavar="SEEDS",
        help="train several seeds (8, 0-7 or 0,3) into OUT/seed-S and keep in OUT the one that "
        "best explains held-out images (selection.json)",
    )  # fmt: skip
    t.add_argument(
        "--device", choices=("auto", "cpu", "cuda"), default="auto",
        help="where to train: a CUDA GPU where torch sees one (auto, the default), or cpu/cuda",
    )  # fmt: skip
    t.add_argument("--no-progress", action="store_true", help="no progress bar")


def run_vae_train(args: argparse.Namespace) -> int:
    from vision.vae import VaeConfig, VaeError
    from vision.vae_train import TrainConfig, load_images, resolve_device, train_vae

    try:
        images = load_images(args.data)
        model_cfg = VaeConfig(
            beta=1.0 if args.beta is None else args.beta,
            capacity=args.capacity,
            capacity_iterations=args.capacity_iterations or VaeConfig().capacity_iterations,
        )
        defaults = TrainConfig()

        def train_one(seed: int, out: Path) -> Any:
            cfg = TrainConfig(
                iterations=args.iterations or defaults.iterations, lr=args.lr or defaults.lr,
                batch=args.batch or defaults.batch, seed=seed, device=args.device,
            )  # fmt: skip
            return train_vae(
                images, out, model_cfg, cfg, progress=not args.no_progress, heldout=HELDOUT
            )

        vae = train_and_select(args.out, seeds_of(args), train_one)
    except VaeError as exc:
        raise CliError(str(exc)) from exc
    kl = ", ".join(f"{v:.2f}" for v in vae.config.kl_per_latent or [])
    print(f"{args.out}: VAE saved (trained on {resolve_device(args.device)}); "
          f"KL per latent (nats): {kl}; held-out explained pixel variance "
          f"{vae.config.heldout_explained_variance:.3f}")  # fmt: skip
    return 0


def run_sae_train(args: argparse.Namespace) -> int:
    from vision.sae_train import SAE_ITERATIONS, train_sae
    from vision.spatial_ae import SaeConfig
    from vision.vae import VaeError
    from vision.vae_train import TrainConfig, load_images

    try:
        images = load_images(args.data)
        model_cfg = SaeConfig(features=args.features)
        model_cfg.validate()

        def train_one(seed: int, out: Path) -> Any:
            cfg = TrainConfig(
                iterations=args.iterations or SAE_ITERATIONS, seed=seed, device=args.device
            )
            return train_sae(images, out, model_cfg, cfg, HELDOUT, progress=not args.no_progress)

        sae = train_and_select(args.out, seeds_of(args), train_one)
    except VaeError as exc:
        raise CliError(str(exc)) from exc
    from explore.goal_spaces import distinct_features

    kept = distinct_features(sae.config.code_std, sae.config.code_corr)
    print(f"{args.out}: spatial autoencoder saved; distinct moving features (the goal space's "
          f"modules): {', '.join(map(str, kept))} of {sae.config.features}; held-out explained "
          f"pixel variance {sae.config.heldout_explained_variance:.3f}")  # fmt: skip
    return 0


HELDOUT = 0.1  # share of a dataset kept out of training to score the model (guess)
SELECTION_FILE = "selection.json"


def seeds_of(args: argparse.Namespace) -> list[int]:
    """The training seeds: ``--seeds`` (as ``ergo experiment`` reads them), else ``--seed``."""
    return parse_seeds(args.seeds) if args.seeds is not None else [args.seed]


def train_and_select(out: Path, seeds: list[int], train_one: Callable[[int, Path], Any]) -> Any:
    """One seed: ``train_one(seed, out)``. Several: each into ``out/seed-S`` (each resumable),
    then the model with the largest held-out explained pixel variance (a criterion that looks
    at images only, never at the ball's true position) is saved into ``out`` itself, and
    ``out/selection.json`` records every seed's value and the choice."""
    if len(seeds) == 1:
        return train_one(seeds[0], out)
    models = {s: train_one(s, out / f"seed-{s}") for s in seeds}
    scores = {s: float(m.config.heldout_explained_variance) for s, m in models.items()}
    best = max(seeds, key=lambda s: (scores[s], -s))
    models[best].save(out)
    from explore.store import atomic_write_text

    record = {"criterion": "heldout_explained_variance", "scores": scores, "chosen": best}
    atomic_write_text(out / SELECTION_FILE, json.dumps(record, indent=1))
    for s in seeds:
        print(f"seed {s}: held-out explained pixel variance {scores[s]:.3f}"
              f"{'  <- chosen' if s == best else ''}")  # fmt: skip
    return models[best]


def run_dataset_outcomes(args: argparse.Namespace) -> int:
    from explore.dataset import make_outcome_dataset, save_dataset

    if args.n < 1:
        raise CliError(f"--n must be at least 1, got {args.n}")
    if args.out.suffix != ".npz":
        raise CliError(f"--out {args.out}: expected a .npz file name")
    data = make_outcome_dataset(
        args.n, seed=args.seed, progress=not args.no_progress, arm=args.arm,
        render_quality=args.render_quality, distractor=args.distractor,
    )  # fmt: skip
    save_dataset(args.out, data)
    print(f"{args.out}: {args.n} images {data['images'].shape[1:]} with ball positions")
    return 0
