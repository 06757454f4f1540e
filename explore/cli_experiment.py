"""``ergo experiment`` (campaigns of runs), ``ergo vae train`` and ``ergo dataset outcomes``.

A campaign is a folder ``CAMPAIGN/STRATEGY/seed-S`` of ordinary run folders (explore/store.py),
one per (strategy, seed), run on the twin by the usual ``Explorer`` in local processes. It is
resumable: finished runs are skipped, unfinished ones resumed. At the end the final number of
ball cells per strategy (mean +- std over seeds) is printed and written to
``CAMPAIGN/summary.csv``.
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import sys
from pathlib import Path
from typing import Any

from explore.cli import CliError
from explore.cli_explore import parse_key_values

# strategies that need a representation trained beforehand, and the flag that gives it
VAE_FLAGS = {
    "rge-vae": "vae", "mge-vae": "vae", "rge-betavae": "betavae", "mge-betavae": "betavae",
}  # fmt: skip
MAKE_VAE = {
    "vae": "ergo dataset outcomes --n 10000 --out data/outcomes.npz && "
    "ergo vae train --data data/outcomes.npz --out models/vae --beta 1",
    "betavae": "ergo dataset outcomes --n 10000 --out data/outcomes.npz && "
    "ergo vae train --data data/outcomes.npz --out models/betavae --beta 4 --capacity 10",
}


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "experiment",
        help="run a campaign of strategies x seeds on the twin and tabulate the cells reached",
        description="Each (strategy, seed) is a run folder CAMPAIGN/STRATEGY/seed-S; finished "
        "runs are skipped and unfinished ones resumed.",
    )
    p.add_argument("--strategies", required=True, help="comma-separated, e.g. rpe,rge-efr")
    p.add_argument("--seeds", default="0", help="comma-separated seeds (default 0)")
    p.add_argument("--episodes", type=int, required=True, help="episodes per run")
    p.add_argument("--out", type=Path, required=True, help="campaign folder")
    p.add_argument("--jobs", type=int, default=1, help="runs in parallel (processes)")
    p.add_argument("--vae", type=Path, help="VAE model for the *-vae strategies")
    p.add_argument("--betavae", type=Path, help="beta-VAE model for the *-betavae strategies")
    p.add_argument(
        "--option", action="append", default=[], metavar="KEY=JSON",
        help="strategy option for every goal-exploration run, e.g. bootstrap=100",
    )  # fmt: skip
    p.add_argument("--no-progress", action="store_true", help="no progress bars")
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
    t.add_argument("--lr", type=float, default=None, help="Adam learning rate (default 1e-3)")
    t.add_argument("--batch", type=int, default=None, help="batch size (default 64)")
    t.add_argument("--seed", type=int, default=0, help="random seed")
    t.add_argument("--no-progress", action="store_true", help="no progress bar")
    t.set_defaults(func=run_vae_train)

    d = sub.add_parser("dataset", help="datasets rendered on the twin")
    dsub = d.add_subparsers(dest="dataset_command", metavar="COMMAND")
    dsub.required = True
    o = dsub.add_parser(
        "outcomes", help="render ball-on-ring scenes with random arm poses (VAE training data)"
    )
    o.add_argument("--n", type=int, default=10000, help="number of scenes (default 10000)")
    o.add_argument("--out", type=Path, required=True, help="output .npz")
    o.add_argument("--seed", type=int, default=0, help="random seed")
    o.add_argument("--no-progress", action="store_true", help="no progress bar")
    o.set_defaults(func=run_dataset_outcomes)


# ---- campaigns ------------------------------------------------------------------------------
def _csv_list(text: str, what: str) -> list[str]:
    items = [s.strip() for s in text.split(",") if s.strip()]
    if not items:
        raise CliError(f"--{what}: give at least one value")
    return items


def strategy_options(
    name: str, vae: Path | None, betavae: Path | None, common: dict[str, Any]
) -> dict[str, Any]:
    """Options of one strategy in a campaign; raises CliError naming the command that makes a
    missing VAE."""
    opts: dict[str, Any] = {} if name == "rpe" else dict(common)
    flag = VAE_FLAGS.get(name)
    if flag is not None:
        path = vae if flag == "vae" else betavae
        if path is None:
            raise CliError(f"{name} needs --{flag} PATH; make one with: {MAKE_VAE[flag]}")
        if not path.exists():
            raise CliError(f"--{flag} {path}: no such file or folder; make one with: "
                           f"{MAKE_VAE[flag]}")  # fmt: skip
        opts["vae"] = str(path.resolve())
    return opts


def run_one(
    run_dir: str, strategy: str, options: dict[str, Any], seed: int, episodes: int, progress: bool
) -> tuple[str, int, int]:
    """Run (or resume) one (strategy, seed) until ``episodes``; returns (strategy, seed, final
    ball cells). Runs in a worker process."""
    from explore.episode import EpisodeConfig
    from explore.explorer import Explorer
    from explore.rig import RigConfig, make_rig
    from explore.store import RunStore
    from explore.strategies import make_strategy

    path = Path(run_dir)
    if RunStore.is_run(path):
        store = RunStore.open(path)
        config = store.config
        config["episodes"] = episodes
    else:
        config = {
            "rig": {"name": "sim", "rig_id": "twin", "options": {}},
            "strategy": {"name": strategy, "options": options},
            "seed": seed,
            "episodes": episodes,
            "episode": dataclasses.asdict(EpisodeConfig()),
        }
        store = None
    strat = make_strategy(config["strategy"]["name"], **config["strategy"]["options"])
    rig = make_rig(RigConfig(**config["rig"]))
    if store is None:
        store = RunStore.create(path, config)
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=episodes, initial=len(store), unit="ep", mininterval=2.0,
                   desc=f"{strategy} s{seed}", file=sys.stderr)  # fmt: skip

    def on_episode(p: Any) -> None:
        bar.n = p.episode  # type: ignore[union-attr]
        bar.set_postfix(cells=p.ball_cells, phase=p.phase, refresh=False)  # type: ignore[union-attr]
        bar.update(0)  # type: ignore[union-attr]

    explorer = Explorer(
        rig, strat, store, seed=int(config["seed"]),
        episode_config=EpisodeConfig(**config.get("episode", {})),
        on_episode=on_episode if bar else None,
    )  # fmt: skip
    try:
        explorer.run(episodes)
    finally:
        store.close()
        if bar:
            bar.close()
    cells = int(explorer.metrics.rows[-1]["ball_cells"]) if explorer.metrics.rows else 0  # type: ignore[arg-type]
    return strategy, seed, cells


def final_cells(run_dir: Path) -> tuple[int, int]:
    """(episodes, final ball cells) of a run from its metrics.csv; (0, 0) when absent."""
    from explore.metrics import read_metrics

    path = run_dir / "metrics.csv"
    if not path.exists():
        return 0, 0
    m = read_metrics(path)
    if len(m["episode"]) == 0:
        return 0, 0
    return len(m["episode"]), int(m["ball_cells"][-1])


def run_campaign(
    out: Path,
    strategies: list[str],
    seeds: list[int],
    episodes: int,
    jobs: int = 1,
    vae: Path | None = None,
    betavae: Path | None = None,
    options: dict[str, Any] | None = None,
    progress: bool = False,
) -> list[dict[str, Any]]:
    """Run every (strategy, seed) not finished yet; returns the summary rows (and writes
    ``out/summary.csv``)."""
    from explore.store import RunStore, RunStoreError
    from explore.strategies import STRATEGIES

    for name in strategies:
        if name not in STRATEGIES:
            raise CliError(f"unknown strategy {name!r}; choose among {', '.join(STRATEGIES)}")
    opts = {s: strategy_options(s, vae, betavae, options or {}) for s in strategies}
    todo = []
    for s in strategies:
        for seed in seeds:
            run_dir = out / s / f"seed-{seed}"
            if RunStore.is_run(run_dir):
                try:
                    meta = RunStore.read_meta(run_dir)
                except RunStoreError as exc:
                    raise CliError(str(exc)) from exc
                cfg = meta["config"]
                if cfg["strategy"]["name"] != s or int(cfg["seed"]) != seed:
                    raise CliError(f"{run_dir} holds another run ({cfg['strategy']['name']}, "
                                   f"seed {cfg['seed']})")  # fmt: skip
                if final_cells(run_dir)[0] >= episodes:
                    continue  # finished
            todo.append((str(run_dir), s, opts[s], seed, episodes, progress))
    out.mkdir(parents=True, exist_ok=True)
    if jobs <= 1 or len(todo) <= 1:
        for job in todo:
            run_one(*job)
    else:
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor

        ctx = multiprocessing.get_context("spawn")  # no inherited GL or torch thread state
        with ProcessPoolExecutor(max_workers=jobs, mp_context=ctx) as pool:
            futures = [pool.submit(run_one, *job) for job in todo]
            for f in futures:
                f.result()
    return write_summary(out, strategies, seeds)


def write_summary(out: Path, strategies: list[str], seeds: list[int]) -> list[dict[str, Any]]:
    """Final ball cells per strategy over seeds -> ``out/summary.csv``; returns the rows."""
    import numpy as np

    rows = []
    for s in strategies:
        per_seed = [final_cells(out / s / f"seed-{seed}") for seed in seeds]
        cells = np.array([c for _, c in per_seed], dtype=float)
        rows.append({
            "strategy": s,
            "seeds": len(seeds),
            "episodes": min(n for n, _ in per_seed),
            "cells_mean": round(float(cells.mean()), 2),
            "cells_std": round(float(cells.std(ddof=1)) if len(cells) > 1 else 0.0, 2),
            "cells_per_seed": " ".join(str(int(c)) for c in cells),
        })  # fmt: skip
    with open(out / "summary.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    return rows


def format_table(rows: list[dict[str, Any]]) -> str:
    lines = [f"{'strategy':<14} {'episodes':>8} {'ball cells (mean ± std)':>24}  per seed"]
    for r in rows:
        cells = f"{r['cells_mean']:.1f} ± {r['cells_std']:.1f}"
        lines.append(f"{r['strategy']:<14} {r['episodes']:>8} {cells:>24}  {r['cells_per_seed']}")
    return "\n".join(lines)


def run_experiment(args: argparse.Namespace) -> int:
    if args.episodes < 1:
        raise CliError(f"--episodes must be at least 1, got {args.episodes}")
    if args.jobs < 1:
        raise CliError(f"--jobs must be at least 1, got {args.jobs}")
    strategies = _csv_list(args.strategies, "strategies")
    try:
        seeds = [int(s) for s in _csv_list(args.seeds, "seeds")]
    except ValueError as exc:
        raise CliError(f"--seeds must be integers: {exc}") from exc
    rows = run_campaign(
        args.out, strategies, seeds, args.episodes, args.jobs, args.vae, args.betavae,
        parse_key_values(args.option, "--option"), progress=not args.no_progress,
    )  # fmt: skip
    print(format_table(rows))
    print(f"summary: {args.out / 'summary.csv'}")
    return 0


# ---- representation and dataset -------------------------------------------------------------
def run_vae_train(args: argparse.Namespace) -> int:
    from vision.vae import VaeConfig, VaeError
    from vision.vae_train import TrainConfig, load_images, train_vae

    try:
        images = load_images(args.data)
        model_cfg = VaeConfig(
            beta=1.0 if args.beta is None else args.beta,
            capacity=args.capacity,
        )
        defaults = TrainConfig()
        train_cfg = TrainConfig(
            iterations=args.iterations or defaults.iterations,
            lr=args.lr or defaults.lr,
            batch=args.batch or defaults.batch,
            seed=args.seed,
        )
        vae = train_vae(images, args.out, model_cfg, train_cfg, progress=not args.no_progress)
    except VaeError as exc:
        raise CliError(str(exc)) from exc
    kl = ", ".join(f"{v:.2f}" for v in vae.config.kl_per_latent or [])
    print(f"{args.out}: VAE saved; KL per latent (nats): {kl}")
    return 0


def run_dataset_outcomes(args: argparse.Namespace) -> int:
    from explore.dataset import make_outcome_dataset, save_dataset

    if args.n < 1:
        raise CliError(f"--n must be at least 1, got {args.n}")
    if args.out.suffix != ".npz":
        raise CliError(f"--out {args.out}: expected a .npz file name")
    data = make_outcome_dataset(args.n, seed=args.seed, progress=not args.no_progress)
    save_dataset(args.out, data)
    print(f"{args.out}: {args.n} images {data['images'].shape[1:]} with ball positions")
    return 0
