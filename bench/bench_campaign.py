"""A reference campaign timed end to end, and the paper's campaign extrapolated from it.

Runs ``ergo experiment`` (the command a user runs: local backend, one process a trial) over
rpe, rge-efr and rge-vae x 2 seeds x 1000 episodes on 2 workers, and prints its wall time and
each strategy's cost per episode (the trials' own start and end times, ``trial.json``). The
paper's campaign, 5 strategies x 8 seeds x 5000 episodes = 200k episodes on the same 2
workers, is then extrapolated from those costs: rpe; rge-efr (and mge-efr, the same loop);
rge-vae (and rge-online, whose goal episodes are rge-vae's, plus its VAE training once per
seed, ``--online-training-s``, default the 700 iterations measured by ``--time-training``).

    .venv/bin/python bench/bench_campaign.py [--episodes 1000] [--seeds 2] [--jobs 2]
        [--vae MODEL] [--time-training] [--out DIR]

rge-vae's model: ``--vae`` (default an untrained VAE of the paper's architecture, which encodes
at the same cost as a trained one).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from explore.runs.layout import TRIAL_FILE

STRATEGIES = ("rpe", "rge-efr", "rge-vae")
PAPER_SEEDS, PAPER_EPISODES, PAPER_WORKERS = 8, 5000, 2
# the paper's five strategies, each timed as the reference strategy whose loop it runs
PAPER = {"rpe": "rpe", "rge-efr": "rge-efr", "mge-efr": "rge-efr", "rge-vae": "rge-vae",
         "rge-online": "rge-vae"}  # fmt: skip
ONLINE_BOOTSTRAP = 2000  # rge-online trains its VAE once, on its first 2000 outcome images


def ergo() -> list[str]:
    return [sys.executable, "-c", "import sys; from explore.cli import main; sys.exit(main())"]


def untrained_vae(folder: Path) -> Path:
    """An untrained VAE of the paper's architecture, saved in ``folder`` (timing only)."""
    import torch

    from vision.vae import Vae

    torch.manual_seed(0)
    return Vae().save(folder)


def time_online_training() -> float:
    """Seconds rge-online's VAE training takes here (its default schedule, 2000 images)."""
    import numpy as np

    from explore.learner.strategies import make_strategy
    from explore.rigs.arena import TWIN_ARENA
    from vision.vae_train import train_vae

    strategy = make_strategy("rge-online", scene=TWIN_ARENA)
    images = np.random.default_rng(0).integers(0, 256, (ONLINE_BOOTSTRAP, 64, 64, 3), np.uint8)
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        train_vae(images, tmp, *strategy._configs, progress=False)
        return time.perf_counter() - t0


def trial_costs(out: Path, strategies: list[str]) -> dict[str, float]:
    """Mean wall seconds per episode of each strategy's trials (their trial.json times, which
    include the worker's start: the rig, the strategy, the model)."""
    costs = {}
    for s in strategies:
        per = []
        for run in sorted((out / s).glob("seed-*")):
            t = json.loads((run / TRIAL_FILE).read_text())
            per.append((t["finished"] - t["started"]) / (t["episodes"] - t["resumed_from"]))
        costs[s] = sum(per) / len(per)
    return costs


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--episodes", type=int, default=1000)
    ap.add_argument("--seeds", type=int, default=2)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--vae", type=Path, default=None)
    ap.add_argument("--out", type=Path, default=None, help="campaign folder (default: temporary)")
    ap.add_argument("--time-training", action="store_true", help="measure rge-online's training")
    ap.add_argument("--online-training-s", type=float, default=None)
    args = ap.parse_args()

    with tempfile.TemporaryDirectory() as tmp:
        out = args.out or Path(tmp) / "campaign"
        vae = args.vae or untrained_vae(Path(tmp) / "vae")
        cmd = [
            *ergo(), "experiment", "--strategies", ",".join(STRATEGIES), "--seeds", str(args.seeds),
            "--episodes", str(args.episodes), "--out", str(out), "--jobs", str(args.jobs),
            "--vae", str(vae), "--no-progress", "--no-report",
        ]  # fmt: skip
        t0 = time.perf_counter()
        subprocess.run(cmd, check=True, env=os.environ | {"MUJOCO_GL": "egl"})
        wall = time.perf_counter() - t0
        costs = trial_costs(out, list(STRATEGIES))
    n = len(STRATEGIES) * args.seeds * args.episodes
    print(f"reference campaign: {len(STRATEGIES)} strategies x {args.seeds} seeds x "
          f"{args.episodes} episodes = {n} episodes on {args.jobs} workers: {wall:.0f} s wall, "
          f"{n / wall:.1f} episodes/s in all")  # fmt: skip
    for s, c in costs.items():
        print(f"  {s:8s} {1000 * c:6.1f} ms per episode per worker ({1 / c:5.1f} episodes/s)")
    training = args.online_training_s
    if training is None and args.time_training:
        training = time_online_training()
        print(f"rge-online's VAE training (700 iterations, 2000 images): {training:.0f} s")
    per_seed = {s: PAPER_EPISODES * costs[ref] for s, ref in PAPER.items()}
    if training is not None:
        per_seed["rge-online"] += training
    total = PAPER_SEEDS * sum(per_seed.values()) / PAPER_WORKERS
    print(f"paper's campaign ({len(PAPER)} strategies x {PAPER_SEEDS} seeds x {PAPER_EPISODES} "
          f"episodes = {len(PAPER) * PAPER_SEEDS * PAPER_EPISODES} episodes) on "
          f"{PAPER_WORKERS} workers, extrapolated: {total / 60:.0f} min"
          f"{'' if training is not None else ' (rge-online training not counted)'} "
          f"(target <= 60 min)")  # fmt: skip


if __name__ == "__main__":
    main()
