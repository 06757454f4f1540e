"""Can the paper's VAE decoder draw the ball at all? (docs/results_vae.md F6, continued)

A supervised check: the decoder of ``vision.vae.Vae`` alone, no encoder, trained with Adam on
the twin's outcome images with the ball's true position as its code (latent 0 and 1: the
ball's x and y in metres divided by 0.17, about the arena's radius, so that they span about
[-1, 1]; the other 8 latents 0), the VAE's loss without its KL term (BCE summed over pixels).
Prints, every 250 iterations, the held-out BCE (the last 10% of the images) minus the mean
training image's, nats per image: below 0 the decoder draws more of the images than the mean
image does.

    .venv/bin/python experiments/vae_decoder_check.py --data outcomes.npz [--iterations 1500]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import torch
from torch.nn import functional as F

from vision.vae import Vae, VaeConfig, to_tensor

BALL_SCALE_M = 0.17  # metres to code units: about the arena's radius (docs/twin.md), a guess


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, required=True, help="dataset .npz (images, ball)")
    ap.add_argument("--iterations", type=int, default=1500)
    ap.add_argument("--lr", type=float, default=1e-3)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    torch.set_num_threads(1)
    torch.manual_seed(args.seed)
    with np.load(args.data) as d:
        images = d["images"]  # (n, 64, 64, 3) BGR uint8
        ball = np.asarray(d["ball"], dtype=np.float32)  # (n, 2) metres
    x = to_tensor(images)  # (n, 3, 64, 64) in [0, 1]
    n = len(x)
    train, test = np.arange(n - n // 10), np.arange(n - n // 10, n)
    code = torch.zeros(n, VaeConfig().latent_dim)
    code[:, :2] = torch.from_numpy(ball / BALL_SCALE_M)
    vae = Vae(VaeConfig())
    params = [*vae.decoder_fc.parameters(), *vae.decoder_conv.parameters()]
    optim = torch.optim.Adam(params, lr=args.lr)
    offset = Vae(VaeConfig(mean_image_offset=True))  # its offset: the mean image's logits
    offset.set_mean_image(images[train])
    mean_logit = offset.pixel_offset.expand(len(test), -1, -1, -1)
    with torch.no_grad():
        base = float(F.binary_cross_entropy_with_logits(mean_logit, x[test], reduction="sum"))
    base /= len(test)
    print(f"the mean training image's held-out BCE: {base:.1f} nats an image")
    rng = np.random.default_rng(args.seed)
    cpu0 = time.process_time()
    for it in range(args.iterations):
        idx = rng.choice(train, 64)
        loss = F.binary_cross_entropy_with_logits(vae.decode(code[idx]), x[idx], reduction="sum")
        optim.zero_grad()
        (loss / len(idx)).backward()
        optim.step()
        if (it + 1) % 250 == 0:
            with torch.no_grad():
                held = F.binary_cross_entropy_with_logits(
                    vae.decode(code[test]), x[test], reduction="sum"
                )
            gap = float(held) / len(test) - base
            cpu = time.process_time() - cpu0
            print(f"it {it + 1:5d} cpu {cpu:5.0f} s  held-out BCE - mean image's: {gap:+.1f} nats",
                  flush=True)  # fmt: skip


if __name__ == "__main__":
    main()
