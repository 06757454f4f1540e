"""A training recipe for the paper's VAE on 2 CPU cores (issue 31, step 3): train one model
per (recipe, seed) and score it along the way.

Every ``--every`` iterations, on the images held out of training (10%, split by the training
seed as ``ergo vae train --seeds`` does): the explained pixel variance (the label-free model
criterion, ``vision.representation_quality``; above 0 the model beats the mean image), the
held-out ELBO terms (BCE and KL, nats per image), and, as a diagnostic only, the held-out R^2
of a linear map from the latent means to the ball's (x, y). CPU seconds are this process's.
Training stops at ``--iterations`` or at ``--cpu-budget`` seconds of CPU; with ``--patience
K`` also after K evaluations without a better held-out ELBO (the best model is the one
reported then).

Recipe knobs: ``--lr`` and ``--lr-final`` (cosine decay from one to the other over
``--iterations``; equal: constant), ``--beta``, ``--capacity`` (nats) over
``--capacity-iterations``, ``--batch``, ``--channels-last``, ``--mean-image-offset``,
``--kl-delay`` and ``--kl-warmup`` (``vision.vae.VaeConfig``).

    .venv/bin/python experiments/vae_recipe.py --data outcomes.npz --seeds 0,1 \
        --iterations 4000 --lr 1e-3 --lr-final 1e-4 --beta 10 --capacity 25 \
        --capacity-iterations 2000 --out runs/vae_recipe/NAME

Writes ``OUT/seed-S.csv`` (one row per evaluation; ``OUT/seed-S/`` holds the training's
checkpoint and log, started afresh each time) and prints a row per evaluation and a summary
per seed.
"""

from __future__ import annotations

import argparse
import csv
import math
import shutil
import sys
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np
import torch
from torch.nn import functional as F

from vision.cli import parse_seeds
from vision.representation_quality import HELDOUT, explained_pixel_variance, heldout_split
from vision.vae import Vae, VaeConfig, kl_per_latent, to_tensor
from vision.vae_train import TrainConfig, fit, make_vae

sys.path.insert(0, str(Path(__file__).resolve().parent))
from script_helpers import linear_r2  # experiments/script_helpers.py


@torch.no_grad()
def heldout_elbo(vae: Vae, images: np.ndarray) -> tuple[float, float]:
    """Mean BCE (summed over pixels) and KL (summed over latents) of ``images``, nats per
    image, with z at the posterior mean (the reconstruction the criterion scores)."""
    x = to_tensor(images)
    mu, logvar = vae.encode(x)
    recon = F.binary_cross_entropy_with_logits(vae.decode(mu), x, reduction="sum") / len(x)
    kl = kl_per_latent(mu, logvar).sum(dim=1).mean()
    return float(recon), float(kl)


def evaluate(vae, images, ball, train, test, mean_image) -> dict[str, float]:
    """The scores of one evaluation (module docstring); leaves ``vae`` in training mode."""
    vae.eval()
    z_test = vae.encode_bgr(images[test])
    ev = explained_pixel_variance(lambda _: vae.decode_bgr(z_test), images[test], mean_image)
    recon, kl = heldout_elbo(vae, images[test])
    z_fit = vae.encode_bgr(images[train[:1000]])
    r2 = linear_r2(z_fit, ball[train[:1000]], z_test, ball[test], pooled=False)
    vae.train()
    return {"ev": ev, "recon": recon, "kl": kl, "elbo": recon + kl, "r2": r2}


def train_one(seed: int, images, ball, args) -> list[dict[str, float]]:
    """One training by ``vision.vae_train.fit`` (the loop of ``ergo vae train``) into
    ``OUT/seed-S`` (started afresh), scored every ``--every`` iterations."""
    train, test = heldout_split(len(images), HELDOUT, seed)
    mean_image = images[train].astype(np.float64).mean(axis=0)
    settings = asdict(VaeConfig(beta=args.beta, capacity=args.capacity,
                                capacity_iterations=args.capacity_iterations,
                                mean_image_offset=args.mean_image_offset,
                                kl_delay=args.kl_delay, kl_warmup=args.kl_warmup))  # fmt: skip
    config = TrainConfig(
        iterations=args.iterations, lr=args.lr, lr_final=args.lr_final, batch=args.batch,
        seed=seed, checkpoint_every=args.iterations, threads=args.threads,
        channels_last=args.channels_last,
    )  # fmt: skip
    folder = args.out / f"seed-{seed}"
    shutil.rmtree(folder, ignore_errors=True)
    rows: list[dict[str, float]] = []
    best = {"elbo": math.inf, "since": 0, "row": None}
    cpu0 = time.process_time()

    def after_step(vae: Vae, done: int) -> bool:
        cpu = time.process_time() - cpu0
        last = done == args.iterations or cpu >= args.cpu_budget
        if done % args.every and not last:
            return False
        row = {"seed": seed, "iteration": done, "cpu_s": round(cpu, 1),
               "lr": config.lr_at(done - 1),
               **evaluate(vae, images, ball, train, test, mean_image)}  # fmt: skip
        rows.append(row)
        print(f"seed {seed} it {done:5d} cpu {cpu:6.0f} s  lr {row['lr']:.1e}  "
              f"EV {row['ev']:+.3f}  R2 {row['r2']:.3f}  BCE {row['recon']:.1f}  "
              f"KL {row['kl']:.1f}", flush=True)  # fmt: skip
        if row["elbo"] < best["elbo"]:
            best.update(elbo=row["elbo"], since=0, row=row)
        else:
            best["since"] += 1
        if args.patience and best["since"] >= args.patience:
            print(f"seed {seed}: no better held-out ELBO in {args.patience} evaluations")
            return True
        return last

    vae = fit(lambda s: make_vae(s, images[train]), settings, images[train], folder, config,
              progress=False, after_step=after_step)  # fmt: skip
    if args.patience and best["row"] is not None:  # the model early stopping keeps
        rows.append({**best["row"], "kept": 1})
    if args.figures:
        save_reconstructions(vae, images[test[:8]], args.out / f"seed-{seed}.png")
    return rows


def save_reconstructions(vae: Vae, images: np.ndarray, path: Path) -> None:
    """Held-out images (top row) and the model's reconstructions from the latent means (bottom
    row), 4x enlarged, as one PNG."""
    import cv2

    vae.eval()
    rec = vae.decode_bgr(vae.encode_bgr(images))
    rows = [np.concatenate(list(r), axis=1) for r in (images, rec)]
    grid = np.concatenate(rows, axis=0)
    cv2.imwrite(str(path), cv2.resize(grid, None, fx=4, fy=4, interpolation=cv2.INTER_NEAREST))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, required=True, help="dataset .npz (images, ball)")
    ap.add_argument("--out", type=Path, required=True, help="folder for seed-S.csv")
    ap.add_argument("--seeds", default="0-0", help="training seeds: 0,1 or 0-7 (ergo's syntax)")
    ap.add_argument("--iterations", type=int, default=4000)
    ap.add_argument("--cpu-budget", type=float, default=600.0, help="CPU seconds per seed")
    ap.add_argument("--every", type=int, default=500)
    ap.add_argument("--patience", type=int, default=0, help="0: no early stop")
    ap.add_argument("--lr", type=float, default=1e-3)
    ap.add_argument("--lr-final", type=float, default=1e-3)
    ap.add_argument("--batch", type=int, default=64)
    ap.add_argument("--beta", type=float, default=1.0)
    ap.add_argument("--capacity", type=float, default=None)
    ap.add_argument("--capacity-iterations", type=int, default=2000)
    ap.add_argument("--channels-last", action="store_true")
    ap.add_argument(
        "--mean-image-offset",
        action="store_true",
        help="the decoder starts from the mean training image (vision/vae.py)",
    )
    ap.add_argument("--kl-delay", type=int, default=0, help="iterations without the KL term")
    ap.add_argument(
        "--kl-warmup",
        type=int,
        default=0,
        help="iterations over which the KL weight then rises to 1",
    )
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--figures", action="store_true", help="OUT/seed-S.png: reconstructions")
    args = ap.parse_args()
    seeds = parse_seeds(args.seeds)
    with np.load(args.data, allow_pickle=False) as z:
        images, ball = z["images"], z["ball"][:, :2]
    args.out.mkdir(parents=True, exist_ok=True)
    print(f"recipe: {vars(args)}")
    for seed in seeds:
        rows = train_one(seed, images, ball, args)
        with open(args.out / f"seed-{seed}.csv", "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=list(rows[-1]))
            w.writeheader()
            w.writerows(rows)
        r = rows[-1]
        print(f"SUMMARY seed {seed}: {r['iteration']} it, {r['cpu_s']:.0f} CPU s, "
              f"EV {r['ev']:+.3f}, R2 {r['r2']:.3f}", flush=True)  # fmt: skip


if __name__ == "__main__":
    main()
