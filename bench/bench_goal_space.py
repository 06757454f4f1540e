"""How faithful a goal space is to the ball's position, on an outcome database.

A goal exploration reaches new ball positions only if (1) nearest neighbours in its goal space
are near in the arena, since the inverse model replays the parameters of the nearest stored
outcome, and (2) goals drawn uniformly in the bounds of the outcomes seen land evenly along
the ball's ring. For each goal space this prints, over the images of ``--data``
(``ergo dataset outcomes``):

- the distance in the arena between each outcome's ball and the ball of its nearest neighbour
  in the goal space (median and 90th percentile, mm; the ball's own (x, y) is the bound);
- for 20000 goals drawn uniformly in the space's bounds: the entropy of the ring angle of the
  outcome nearest to each goal, normalised to 1 for even coverage of 36 sectors.

Spaces: the ball's (x, y) (the bound), the engineered wrap-safe features (r, cos, sin), and
with ``--vae`` its 10 latent means as RGE uses them, MGE's first module (the two latents of
largest KL) and the latent means z-scored over the database.

    .venv/bin/python bench/bench_goal_space.py --data outcomes.npz --vae models/vae
"""

from __future__ import annotations

import argparse

import numpy as np
from scipy.spatial import cKDTree

from explore.learner.goal_spaces import kl_ranked_modules, wrap_safe_features

N_GOALS = 20_000  # goals drawn per space (enough for a stable entropy; guess)
N_SECTORS = 36  # 10-degree sectors of the ring for the coverage entropy


def neighbour_error_mm(features: np.ndarray, ball: np.ndarray) -> tuple[float, float]:
    """Median and 90th percentile over outcomes of the arena distance (mm) between an
    outcome's ball and its nearest other outcome's ball in ``features`` (n, d); ball (n, 2) m."""
    _, idx = cKDTree(features).query(features, k=2)
    err = np.linalg.norm(ball - ball[idx[:, 1]], axis=1) * 1000.0
    return float(np.median(err)), float(np.percentile(err, 90))


def goal_coverage(features: np.ndarray, ball: np.ndarray, rng: np.random.Generator) -> float:
    """Normalised entropy (0..1) of the ring angle of the outcomes nearest to uniform goals."""
    goals = rng.uniform(features.min(axis=0), features.max(axis=0), (N_GOALS, features.shape[1]))
    _, idx = cKDTree(features).query(goals)
    angle = np.arctan2(ball[idx, 1], ball[idx, 0])
    counts, _ = np.histogram(angle, bins=N_SECTORS, range=(-np.pi, np.pi))
    p = counts[counts > 0] / counts.sum()
    return float(-(p * np.log(p)).sum() / np.log(N_SECTORS))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", required=True, help="outcome database (.npz)")
    parser.add_argument("--vae", help="VAE model folder (ergo vae train --out)")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()

    with np.load(args.data) as data:
        images, ball = data["images"], data["ball"]
    seen = np.all(np.isfinite(ball), axis=1)
    images, ball = images[seen], ball[seen]
    spaces = {"ball (x, y): the bound": ball, "engineered (r, cos, sin)": wrap_safe_features(ball)}
    if args.vae:
        from vision.vae import load_vae

        vae = load_vae(args.vae)
        mu = vae.encode_bgr(images)
        kl = vae.mean_kl_per_latent(images)
        first = kl_ranked_modules(kl)[0]
        spaces["VAE latent means (RGE)"] = mu
        spaces[f"VAE latents {first[0]},{first[1]} (MGE module 1)"] = mu[:, first]
        if vae.config.latent_mean is not None:  # as rge-vae's latents="zscore" uses them
            mean, std = np.asarray(vae.config.latent_mean), np.asarray(vae.config.latent_std)
            spaces["VAE latent means z-scored (saved stats)"] = (mu - mean) / std
        else:
            spaces["VAE latent means z-scored (these outcomes)"] = (mu - mu.mean(0)) / mu.std(0)
        print("KL per latent (nats):", " ".join(f"{k:.2f}" for k in kl))
        print("spread of latent means:", " ".join(f"{s:.1e}" for s in mu.std(axis=0)))
    print(f"{len(ball)} outcomes of {args.data}")
    print(f"{'goal space':40s} {'NN ball error median':>21s} {'p90':>8s} {'goal coverage':>14s}")
    rng = np.random.default_rng(args.seed)
    for name, features in spaces.items():
        median, p90 = neighbour_error_mm(features, ball)
        cover = goal_coverage(features, ball, rng)
        print(f"{name:40s} {median:18.1f} mm {p90:5.0f} mm {cover:14.3f}")


if __name__ == "__main__":
    main()
