"""What the learned representations of Arm-2-Balls encode (docs/results_armballs.md): for each
model, on scenes it was not trained on (both balls uniform over [-1, 1]^2, the database's
distribution, another seed), how well the ball's and the distractor's positions are predicted
linearly (R^2, with an intercept) from the whole code and from each MGE module, and by the
mean of their nearest neighbours in the code (R^2 on the last quarter of the scenes from the
first three quarters: what a code holds however it is folded, the locality the learner's
nearest-neighbour inverse model relies on), and each latent's KL and strongest correlation
with a position coordinate.

A module is object-aligned when it predicts one ball well and the other not at all: what MGE
needs to give its interest to the ball and take it from the distractor. The labels are a
diagnostic of this table only: no strategy and no model choice sees them.

    .venv/bin/python experiments/armballs_representation.py --vae runs/armballs/models/vae \
        --betavae runs/armballs/models/betavae --sae runs/armballs/models/sae [--n 4000] \
        [--reconstructions docs/img/armballs_reconstructions.png]

``--reconstructions``: a picture of the first 6 scenes (top row) and each VAE's reconstruction
of them (one row per model, in the order given).
"""

from __future__ import annotations

import argparse

import numpy as np
from scipy.spatial import cKDTree
from script_helpers import linear_r2  # experiments/script_helpers.py, beside this script
from script_helpers import r2 as prediction_r2

from explore.learner.goal_spaces import kl_ranked_modules, spatial_goal_space
from explore.rigs.armballs import outcome_dataset
from explore.rigs.rig import RigConfig, rig_options

FACTORS = ("ball x", "ball y", "distractor x", "distractor y")


def r2(x: np.ndarray, y: np.ndarray) -> float:
    """R^2 of the least-squares linear prediction (with intercept) of y (n, k) from x (n, d),
    over all of y's coordinates."""
    return linear_r2(x, y, pooled=True)


def knn_r2(x: np.ndarray, y: np.ndarray, k: int = 5) -> float:
    """R^2 of predicting y (n, m) on the last quarter of the rows by the mean y of the k nearest
    rows of x (n, d) among the first three quarters (Euclidean, in the code's own units)."""
    cut = len(x) * 3 // 4
    _, idx = cKDTree(x[:cut]).query(x[cut:], k)
    return prediction_r2(y[:cut][idx.reshape(len(x) - cut, k)].mean(axis=1), y[cut:], pooled=True)


def describe(name: str, codes: np.ndarray, modules: list[np.ndarray], kl: list[float] | None,
             ball: np.ndarray, dis: np.ndarray) -> None:  # fmt: skip
    truth = np.hstack([ball, dis])
    print(f"## {name}: code of {codes.shape[1]}")
    print(f"whole code: R^2 ball {r2(codes, ball):.3f}, distractor {r2(codes, dis):.3f}; "
          f"nearest-neighbour R^2 ball {knn_r2(codes, ball):.3f}, "
          f"distractor {knn_r2(codes, dis):.3f}")  # fmt: skip
    for k, idx in enumerate(modules):
        x = codes[:, idx]
        print(f"  module {k} {list(map(int, idx))}: R^2 ball {r2(x, ball):.3f}, "
              f"distractor {r2(x, dis):.3f}; nearest-neighbour ball {knn_r2(x, ball):.3f}, "
              f"distractor {knn_r2(x, dis):.3f}")  # fmt: skip
    corr = np.corrcoef(np.hstack([codes, truth]).T)[: codes.shape[1], codes.shape[1] :]
    corr = np.nan_to_num(corr)
    for i in range(codes.shape[1]):
        j = int(np.argmax(np.abs(corr[i])))
        kl_txt = f"KL {kl[i]:.2f}, " if kl is not None else ""
        print(f"  latent {i}: {kl_txt}sd {codes[:, i].std():.3f}, strongest |corr| "
              f"{abs(corr[i, j]):.2f} with {FACTORS[j]}")  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--vae", action="append", default=[], help="a VAE folder (repeatable)")
    ap.add_argument("--betavae", action="append", default=[], help="a beta-VAE folder")
    ap.add_argument("--sae", action="append", default=[], help="a spatial autoencoder folder")
    ap.add_argument("--n", type=int, default=4000, help="held-out scenes (default 4000)")
    ap.add_argument("--seed", type=int, default=12345, help="their seed (not the training's)")
    ap.add_argument("--reconstructions", default=None, help="write the scenes and each VAE's "
                    "reconstructions of them to this .png")  # fmt: skip
    args = ap.parse_args()
    from vision.spatial_ae import load_sae
    from vision.vae import load_vae

    config = RigConfig("arm2balls")
    data = outcome_dataset(config, rig_options(config), args.n, seed=args.seed)
    images, ball, dis = data["images"], data["ball"], data["distractor"]
    vaes = [(path, load_vae(path)) for path in [*args.vae, *args.betavae]]
    for path, vae in vaes:
        kl = vae.config.kl_per_latent
        mu = vae.encode_bgr(images)
        modules = kl_ranked_modules(kl) if kl is not None else []
        describe(path, mu, modules, kl, ball, dis)
    if args.reconstructions:
        import cv2

        shown = images[:6]
        rows = [shown] + [vae.decode_bgr(vae.encode_bgr(shown)) for _, vae in vaes]
        picture = np.concatenate([np.concatenate(list(r), axis=1) for r in rows], axis=0)
        cv2.imwrite(args.reconstructions, cv2.resize(picture, None, fx=3, fy=3,
                                                     interpolation=cv2.INTER_NEAREST))  # fmt: skip
        print("wrote", args.reconstructions)
    for path in args.sae:
        sae = load_sae(path)
        space = spatial_goal_space(sae.encode_bgr, sae.config.code_std, True, sae.config.code_corr)
        describe(path, space.outcomes(images), space.modules, None, ball, dis)


if __name__ == "__main__":
    main()
