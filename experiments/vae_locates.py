"""Does a trained VAE locate the ball, linearly or not? (issue 31, step 3; docs/results_vae.md F11)

For training checkpoints of ``experiments/vae_recipe.py`` or ``ergo vae train`` (a folder's
``checkpoint.pt``), on the images held out of that training (10%, split by the training seed):

- the held-out explained pixel variance (the label-free model criterion);
- the held-out R^2 of the ball's (x, y) from the latent means by a least-squares affine map fitted
  on 1000 training images (the issue's diagnostic, as ``vae_recipe.py`` prints it);
- the same R^2 from the mean ball position of the 10 nearest of those 1000 training images in
  the raw latent means, Euclidean: what RGE-VAE's nearest-neighbour inverse model sees;
- the KL per latent (nats, largest first) over the held-out images.

    .venv/bin/python experiments/vae_locates.py --data outcomes-3000.npz RUN_DIR [RUN_DIR ...]

Prints one Markdown row per checkpoint. Diagnostics only: nothing here picks a model.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import torch

from vision.representation_quality import HELDOUT, explained_pixel_variance, heldout_split
from vision.vae import load_state
from vision.vae_train import CHECKPOINT, make_vae

sys.path.insert(0, str(Path(__file__).resolve().parent))
from script_helpers import linear_r2, r2  # experiments/script_helpers.py

FIT = 1000  # training images the probes are fitted on (as vae_recipe.py)
K = 10  # neighbours of the nearest-neighbour probe


def knn_r2(z_fit: np.ndarray, y_fit: np.ndarray, z_test: np.ndarray, y_test: np.ndarray) -> float:
    """R^2 (mean over the columns) of y_test predicted by the mean y of the ``K`` nearest fit
    rows in z (Euclidean)."""
    d = ((z_test[:, None, :] - z_fit[None, :, :]) ** 2).sum(axis=2)
    nearest = np.argsort(d, axis=1)[:, :K]
    return r2(y_fit[nearest].mean(axis=1), y_test, pooled=False)


def score(folder: Path, images: np.ndarray, ball: np.ndarray, seed: int) -> str:
    state = load_state(folder / CHECKPOINT, "training checkpoint")
    train, test = heldout_split(len(images), HELDOUT, seed)
    vae = make_vae(state["model_config"], images[train])
    vae.load_state_dict(state["model"])
    vae.eval()
    z_test = vae.encode_bgr(images[test])
    mean_image = images[train].astype(np.float64).mean(axis=0)
    ev = explained_pixel_variance(lambda _: vae.decode_bgr(z_test), images[test], mean_image)
    z_fit = vae.encode_bgr(images[train[:FIT]])
    lin = linear_r2(z_fit, ball[train[:FIT]], z_test, ball[test], pooled=False)
    knn = knn_r2(z_fit, ball[train[:FIT]], z_test, ball[test])
    kl = vae.mean_kl_per_latent(images[test])
    kls = " ".join(f"{v:.1f}" for v in sorted(kl, reverse=True)[:5])
    return (f"| {folder} | {state['iteration']} | {ev:+.3f} | {lin:.2f} | {knn:.2f} | "
            f"{kls} |")  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, required=True, help="dataset .npz (images, ball)")
    ap.add_argument("runs", type=Path, nargs="+", help="folders holding a checkpoint.pt, "
                    "named seed-S (S: the training seed)")  # fmt: skip
    args = ap.parse_args()
    torch.set_num_threads(1)
    with np.load(args.data) as z:
        images, ball = z["images"], z["ball"][:, :2]
    print("| model | iterations | held-out explained variance | ball R^2, linear | ball R^2, "
          f"{K} nearest in the latent means | KL per latent, 5 largest (nats) |")  # fmt: skip
    print("|---|---|---|---|---|---|")
    for folder in args.runs:
        print(score(folder, images, ball, int(folder.name.split("-")[-1])), flush=True)


if __name__ == "__main__":
    main()
