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
largest KL) and the latent means z-scored over the database, the latent spaces' coverage
also for goals drawn from the paper's prior N(0, 1) clipped at 2.5; with ``--sae`` the
spatial autoencoder's goal space as rge-sae uses it.

    .venv/bin/python experiments/goal_space.py --data outcomes.npz --vae models/vae
"""

from __future__ import annotations

import argparse

import numpy as np
from scipy.spatial import cKDTree

from explore.learner.goal_spaces import kl_ranked_modules, wrap_safe_features
from explore.learner.strategies.goal_exploration import NORMAL_CLIP
from explore.rigs.arena import R_MAX, R_MIN

N_GOALS = 20_000  # goals drawn per space (enough for a stable entropy; guess)
N_SECTORS = 36  # 10-degree sectors of the ring for the coverage entropy


def neighbour_error_mm(features: np.ndarray, ball: np.ndarray) -> tuple[float, float]:
    """Median and 90th percentile over outcomes of the arena distance (mm) between an
    outcome's ball and its nearest other outcome's ball in ``features`` (n, d); ball (n, 2) m."""
    _, idx = cKDTree(features).query(features, k=2)
    err = np.linalg.norm(ball - ball[idx[:, 1]], axis=1) * 1000.0
    return float(np.median(err)), float(np.percentile(err, 90))


def goal_coverage(
    features: np.ndarray, ball: np.ndarray, rng: np.random.Generator, goals: str = "uniform"
) -> float:
    """Normalised entropy (0..1) of the ring angle of the outcomes nearest to goals drawn
    uniformly in the features' bounds (``goals="uniform"``, the default of every strategy) or
    from N(0, 1) clipped at +-2.5 (``"normal"``, the paper's latent prior)."""
    d = features.shape[1]
    if goals == "normal":
        samples = np.clip(rng.normal(0.0, 1.0, (N_GOALS, d)), -NORMAL_CLIP, NORMAL_CLIP)
    else:
        samples = rng.uniform(features.min(axis=0), features.max(axis=0), (N_GOALS, d))
    _, idx = cKDTree(features).query(samples)
    angle = np.arctan2(ball[idx, 1], ball[idx, 0])
    counts, _ = np.histogram(angle, bins=N_SECTORS, range=(-np.pi, np.pi))
    p = counts[counts > 0] / counts.sum()
    return float(-(p * np.log(p)).sum() / np.log(N_SECTORS))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", required=True, help="outcome database (.npz)")
    parser.add_argument("--vae", help="VAE model folder (ergo vae train --out)")
    parser.add_argument("--sae", help="spatial autoencoder folder (ergo sae train --out)")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()

    with np.load(args.data) as data:
        images, ball = data["images"], data["ball"]
    seen = np.all(np.isfinite(ball), axis=1)
    images, ball = images[seen], ball[seen]
    spaces = {
        "ball (x, y): the bound": ball,
        "engineered (r, cos, sin)": wrap_safe_features(ball, (R_MIN, R_MAX)),
    }
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
    if args.sae:
        from explore.learner.goal_spaces import spatial_goal_space
        from vision.spatial_ae import load_sae

        sae = load_sae(args.sae)
        space = spatial_goal_space(sae.encode_bgr, sae.config.code_std, False, sae.config.code_corr)
        spaces[f"spatial autoencoder features {space.features} (rge-sae)"] = space.outcomes(images)
    print(f"{len(ball)} outcomes of {args.data}")
    print(f"{'goal space':52s} {'NN ball error median':>21s} {'p90':>8s} "
          f"{'goal coverage: uniform':>23s} {'normal':>7s}")  # fmt: skip
    rng = np.random.default_rng(args.seed)
    for name, features in spaces.items():
        median, p90 = neighbour_error_mm(features, ball)
        cover = goal_coverage(features, ball, rng)
        normal = goal_coverage(features, ball, rng, "normal") if "VAE" in name else float("nan")
        print(f"{name:52s} {median:18.1f} mm {p90:5.0f} mm {cover:23.3f} {normal:7.3f}")


if __name__ == "__main__":
    main()
