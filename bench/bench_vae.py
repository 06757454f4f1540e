"""Time on this machine's CPU to a VAE whose latent predicts the ball's position linearly.

Issue 6's benchmark: train on an outcome database (``ergo dataset outcomes``), and after every
``--every`` iterations fit a linear map (least squares with intercept) from the latent means of
the training images to the ball's (x, y) and score it on held-out images (R^2, averaged over x
and y). Prints one row per evaluation: iteration, CPU and wall minutes of training so far, the
loss terms, the held-out R^2; then the first iteration at which R^2 >= ``--target``.

The paper's schedule (Adam lr 1e-5, batch 64, 300k iterations on a GPU) is the baseline: run the
same script with ``--lr 1e-5`` to compare at equal iterations, and ``--device cuda`` on a GPU
(the CPU minutes column then counts the Python process's CPU time only).

    .venv/bin/python bench/bench_vae.py [--data outcomes.npz] [--out /tmp/vae_bench] \
        [--iterations 3000] --every 250 [--beta 1] [--capacity 12 --capacity-iterations 1500]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from vision.vae import VaeConfig
from vision.vae_train import CHECKPOINT, TrainConfig, train_vae

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "experiments"))
from script_helpers import linear_r2  # experiments/script_helpers.py

N_DEFAULT = 3000  # scenes rendered when no dataset is given (about 5 min of CPU; guess: enough)
HELD_OUT = 0.2  # fraction of the images kept out of training and of the linear fit


def resumed_iteration(folder: Path) -> int:
    """Iterations already done by a checkpoint in ``folder`` (0 if none)."""
    ckpt = folder / CHECKPOINT
    if not ckpt.exists():
        return 0
    import torch

    return int(torch.load(ckpt, map_location="cpu", weights_only=True)["iteration"])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--data", type=Path, default=None,
        help="dataset .npz (images, ball); default: render N_DEFAULT scenes into OUT/dataset.npz",
    )  # fmt: skip
    ap.add_argument(
        "--out", type=Path, default=Path("/tmp/ergo-bench-vae"),
        help="model folder (resumed if present)",
    )  # fmt: skip
    ap.add_argument("--iterations", type=int, default=3000)
    ap.add_argument("--every", type=int, default=250)
    ap.add_argument("--lr", type=float, default=1e-3)
    ap.add_argument("--batch", type=int, default=64)
    ap.add_argument("--beta", type=float, default=1.0)
    ap.add_argument("--capacity", type=float, default=None)
    ap.add_argument("--capacity-iterations", type=int, default=2000)
    ap.add_argument("--target", type=float, default=0.9)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--device", choices=("cpu", "cuda", "auto"), default="cpu")
    args = ap.parse_args()

    if args.data is None:
        args.data = args.out / "dataset.npz"
        if not args.data.exists():
            from explore.rigs.sim_dataset import make_outcome_dataset, save_dataset

            save_dataset(args.data, make_outcome_dataset(N_DEFAULT, seed=args.seed))
    with np.load(args.data, allow_pickle=False) as z:
        images, ball = z["images"], z["ball"]
    order = np.random.default_rng(args.seed).permutation(len(images))
    n_test = int(len(images) * HELD_OUT)
    test, train = order[:n_test], order[n_test:]
    model_cfg = VaeConfig(
        beta=args.beta, capacity=args.capacity, capacity_iterations=args.capacity_iterations
    )
    print(
        f"{len(train)} training and {n_test} held-out images; lr {args.lr}, batch {args.batch}, "
        f"beta {args.beta}, capacity {args.capacity} over {args.capacity_iterations} iterations, "
        f"device {args.device}"
    )
    print("iteration  cpu_min  wall_min  loss  recon  kl  heldout_R2")
    done = resumed_iteration(args.out)
    if done:
        print(f"resuming {args.out} at iteration {done}: times count from here")
    cpu0, wall0 = time.process_time(), time.perf_counter()
    reached = None
    for stop in range(args.every, args.iterations + 1, args.every):
        if stop <= done:
            continue  # measured by the run that wrote the checkpoint
        cfg = TrainConfig(
            iterations=stop, lr=args.lr, batch=args.batch, seed=args.seed, device=args.device
        )
        vae = train_vae(images[train], args.out, model_cfg, cfg, progress=False)
        cpu = (time.process_time() - cpu0) / 60
        wall = (time.perf_counter() - wall0) / 60
        z_train, z_test = vae.encode_bgr(images[train]), vae.encode_bgr(images[test])
        r2 = linear_r2(z_train, ball[train], z_test, ball[test], pooled=False)  # mean over x, y
        last = (args.out / "train_log.csv").read_text().strip().splitlines()[-1].split(",")
        print(f"{stop:9d}  {cpu:7.1f}  {wall:8.1f}  {last[1]}  {last[2]}  {last[3]}  {r2:.3f}")
        if reached is None and r2 >= args.target:
            reached = (stop, cpu, wall)
    if reached is None:
        print(f"R^2 >= {args.target} not reached in {args.iterations} iterations")
    else:
        it, cpu, wall = reached
        print(f"R^2 >= {args.target} at iteration {it}: {cpu:.1f} CPU min, {wall:.1f} wall min")


if __name__ == "__main__":
    main()
