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
``--capacity-iterations``, ``--batch``, ``--channels-last``.

    .venv/bin/python experiments/vae_recipe.py --data outcomes.npz --seeds 0,1 \
        --iterations 4000 --lr 1e-3 --lr-final 1e-4 --beta 10 --capacity 25 \
        --capacity-iterations 2000 --out runs/vae_recipe/NAME

Writes ``OUT/seed-S.csv`` (one row per evaluation) and prints a row per evaluation and a
summary per seed.
"""

from __future__ import annotations

import argparse
import csv
import math
import sys
import time
from pathlib import Path

import numpy as np
import torch

from vision.representation_quality import HELDOUT, explained_pixel_variance, heldout_split
from vision.vae import Vae, VaeConfig, kl_per_latent, limit_threads
from vision.vae_train import TrainConfig, batch_tensor

sys.path.insert(0, str(Path(__file__).resolve().parent))
from script_helpers import linear_r2  # experiments/script_helpers.py


@torch.no_grad()
def heldout_elbo(vae: Vae, images: np.ndarray) -> tuple[float, float]:
    """Mean BCE (summed over pixels) and KL (summed over latents) of ``images``, nats per
    image, with z at the posterior mean (the reconstruction the criterion scores)."""
    x = torch.from_numpy(np.ascontiguousarray(images[..., ::-1])).permute(0, 3, 1, 2)
    x = x.float().div_(255.0)
    mu, logvar = vae.encode(x)
    recon = torch.nn.functional.binary_cross_entropy_with_logits(
        vae.decode(mu), x, reduction="sum"
    ) / len(x)
    kl = kl_per_latent(mu, logvar).sum(dim=1).mean()
    return float(recon), float(kl)


def evaluate(vae, images, ball, train, test, mean_image) -> dict[str, float]:
    vae.eval()
    ev = explained_pixel_variance(
        lambda x: vae.decode_bgr(vae.encode_bgr(x)), images[test], mean_image
    )
    recon, kl = heldout_elbo(vae, images[test])
    z_fit = vae.encode_bgr(images[train[:1000]])
    r2 = linear_r2(z_fit, ball[train[:1000]], vae.encode_bgr(images[test]), ball[test],
                   pooled=False)  # fmt: skip
    vae.train()
    return {"ev": ev, "recon": recon, "kl": kl, "elbo": recon + kl, "r2": r2}


def train_one(seed: int, images, ball, args) -> list[dict[str, float]]:
    limit_threads(args.threads)
    train, test = heldout_split(len(images), HELDOUT, seed)
    mean_image = images[train].astype(np.float64).mean(axis=0)
    torch.manual_seed(seed)
    vae = Vae(VaeConfig(beta=args.beta, capacity=args.capacity,
                        capacity_iterations=args.capacity_iterations))  # fmt: skip
    fmt = torch.channels_last if args.channels_last else torch.contiguous_format
    vae = vae.to(memory_format=fmt)
    schedule = TrainConfig(iterations=args.iterations, lr=args.lr, lr_final=args.lr_final)
    optim = torch.optim.Adam(vae.parameters(), lr=args.lr)
    data = torch.from_numpy(np.ascontiguousarray(images[train]))
    rows: list[dict[str, float]] = []
    best, since_best, best_row = math.inf, 0, None
    cpu0 = time.process_time()
    vae.train()
    for it in range(args.iterations):
        for g in optim.param_groups:
            g["lr"] = schedule.lr_at(it)
        idx = np.random.default_rng([seed, it]).integers(0, len(train), args.batch)
        torch.manual_seed(seed * 1_000_003 + it)
        x = batch_tensor(data, torch.from_numpy(idx)).contiguous(memory_format=fmt)
        terms = vae.loss(x, it)
        optim.zero_grad(set_to_none=True)
        terms["loss"].backward()
        optim.step()
        done = it + 1
        cpu = time.process_time() - cpu0
        last = done == args.iterations or cpu >= args.cpu_budget
        if done % args.every == 0 or last:
            scores = evaluate(vae, images, ball, train, test, mean_image)
            row = {"seed": seed, "iteration": done, "cpu_s": round(cpu, 1),
                   "lr": schedule.lr_at(it), **scores}  # fmt: skip
            rows.append(row)
            print(f"seed {seed} it {done:5d} cpu {cpu:6.0f} s  lr {row['lr']:.1e}  "
                  f"EV {row['ev']:+.3f}  R2 {row['r2']:.3f}  BCE {row['recon']:.1f}  "
                  f"KL {row['kl']:.1f}", flush=True)  # fmt: skip
            if row["elbo"] < best:
                best, since_best, best_row = row["elbo"], 0, row
            else:
                since_best += 1
            if args.patience and since_best >= args.patience:
                print(f"seed {seed}: no better held-out ELBO in {args.patience} evaluations")
                break
        if last:
            break
    if args.patience and best_row is not None:  # the model early stopping keeps
        rows.append({**best_row, "kept": 1})
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
    ap.add_argument("--seeds", default="0", help="training seeds: 0,1 or 0-7")
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
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--figures", action="store_true", help="OUT/seed-S.png: reconstructions")
    args = ap.parse_args()
    if "-" in args.seeds:
        lo, hi = (int(v) for v in args.seeds.split("-"))
        seeds = list(range(lo, hi + 1))
    else:
        seeds = [int(v) for v in args.seeds.split(",")]
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
