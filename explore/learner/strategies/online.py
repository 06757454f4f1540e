"""RGE-Online: goal exploration in a VAE trained on the robot's own outcome images.

A bootstrap of random episodes (2000 by default, as the paper's online variant on the rig),
then a VAE trained on the bootstrap's outcome images, then random goal exploration in its
latent space. The training is deterministic given the records (seeded batches, noise and
initial weights; ``vision/vae_train.py``), so a resumed run that replays its history through
``update`` retrains the same model (at the cost of the training time) and continues exactly.
"""

from __future__ import annotations

import tempfile
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from explore.learner.dmp import N_PARAMS
from explore.learner.scene import Scene
from explore.learner.strategies.base import StrategyError
from explore.learner.strategies.goal_exploration import (
    GoalExploration,
    GoalExplorationOptions,
    latent_space,
)

ONLINE_BOOTSTRAP = 2000  # paper: 2000 random episodes before the online VAE (rig)
# CPU schedule, the one of the pre-trained VAE in docs/results_vae.md: Adam lr 1e-3,
# batch 64, beta 10 with a KL capacity rising to 10 nats over 500 iterations, 700 iterations.
# The paper used 200k iterations of batch 32 at lr 1e-5 on a GPU. The plain VAE (beta 1) at
# 1500 iterations, the first default, collapsed on a bootstrap's images: total KL 0.11 nats at
# 300 iterations, 0.014 at 900 (bench_vae on RPE seed 0's first 2000 outcome images, which are
# rge-online's bootstrap for the same seed).
ONLINE_ITERATIONS = 700
ONLINE_BETA = 10.0
ONLINE_CAPACITY = 10.0  # nats
ONLINE_CAPACITY_ITERATIONS = 500


@dataclass(frozen=True)
class OnlineOptions(GoalExplorationOptions):
    """The goal-exploration options (``bootstrap`` 2000 by default), and the online VAE's:
    ``vae_iterations`` (700), ``vae_beta`` (10), ``vae_capacity`` (10 nats; null for a plain
    beta * KL loss), ``vae_capacity_iterations`` (500), ``vae_seed`` (0), ``latents`` ("raw" or
    "zscore" over the bootstrap's own outcome images).

    The training aids of docs/results.md F6 (``vision.vae.VaeConfig``,
    ``vision.vae_train.TrainConfig``), all off by default so that runs made without them
    (docs/results.md F5) resume and rerun unchanged: ``vae_lr`` (1e-3) and ``vae_lr_final``
    (null: constant; else a half-cosine decay to it), ``vae_channels_last``,
    ``vae_mean_image_offset`` (the decoder over the bootstrap images' mean), ``vae_kl_delay``
    and ``vae_kl_warmup`` (iterations). F6's recipe: ``vae_iterations`` 3000, ``vae_lr_final``
    1e-5, ``vae_channels_last`` and ``vae_mean_image_offset`` true, ``vae_kl_delay`` and
    ``vae_kl_warmup`` 1000 (``experiments/twin_final.sh``)."""

    bootstrap: int = ONLINE_BOOTSTRAP
    vae_iterations: int = ONLINE_ITERATIONS
    vae_beta: float = ONLINE_BETA
    vae_capacity: float | None = ONLINE_CAPACITY
    vae_capacity_iterations: int = ONLINE_CAPACITY_ITERATIONS
    vae_seed: int = 0
    latents: Literal["raw", "zscore"] = "raw"
    vae_lr: float = 1e-3
    vae_lr_final: float | None = None
    vae_channels_last: bool = False
    vae_mean_image_offset: bool = False
    vae_kl_delay: int = 0
    vae_kl_warmup: int = 0


class OnlineLatentGoalExploration(GoalExploration):
    """Goal exploration in a VAE trained on the bootstrap's outcome images (options:
    ``OnlineOptions``)."""

    name = "rge-online"
    Options = OnlineOptions

    def __init__(self, n_params: int = N_PARAMS, *, scene: Scene, **options: Any) -> None:
        super().__init__(n_params, scene=scene, **options)
        if self.bootstrap < 1:
            raise StrategyError(f"{self.name}: bootstrap must be at least 1 (the VAE's data)")
        self._configs = self._vae_configs()  # bad options fail now, not after the bootstrap
        self.vae = None

    def make_space(self) -> None:
        return None  # trained after the bootstrap

    def after_pending(self) -> None:
        if len(self._pending) < self.bootstrap:
            return
        from vision.vae_train import train_vae

        images = np.stack([r.image for r in self._pending])
        with tempfile.TemporaryDirectory(prefix="ergo-online-vae-") as tmp:
            self.vae = train_vae(
                images, tmp, *self._configs,
                progress=False,
            )  # fmt: skip
        self._init_space(latent_space(self.vae, self.modular, self.settings.latents, self.name))
        pending, self._pending = self._pending, []
        for rec in pending:
            self._learn(rec)

    def _vae_configs(self) -> tuple[Any, Any]:
        """The online VAE's ``VaeConfig`` and ``TrainConfig`` from the options (a bad value: a
        StrategyError)."""
        from vision.vae import VaeConfig, VaeError
        from vision.vae_train import TrainConfig

        s = self.settings
        try:
            model = VaeConfig(
                beta=s.vae_beta,
                capacity=s.vae_capacity,
                capacity_iterations=s.vae_capacity_iterations,
                mean_image_offset=s.vae_mean_image_offset,
                kl_delay=s.vae_kl_delay,
                kl_warmup=s.vae_kl_warmup,
            )
            train = TrainConfig(
                iterations=s.vae_iterations, lr=s.vae_lr, lr_final=s.vae_lr_final,
                seed=s.vae_seed, channels_last=s.vae_channels_last,
            )  # fmt: skip
            model.validate()
            train.validate()
        except (TypeError, ValueError, VaeError) as exc:
            raise StrategyError(f"{self.name}: bad VAE option: {exc}") from exc
        return model, train

    def phase(self) -> str:
        return "bootstrap" if self.space is None else "rge-online"
