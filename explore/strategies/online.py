"""RGE-Online: goal exploration in a VAE trained on the robot's own outcome images.

A bootstrap of random episodes (2000 by default, as the paper's online variant on the rig),
then a VAE trained on the bootstrap's outcome images, then random goal exploration in its
latent space. The training is deterministic given the records (seeded batches, noise and
initial weights; ``vision/vae_train.py``), so a resumed run that replays its history through
``update`` retrains the same model (at the cost of the training time) and continues exactly.
"""

from __future__ import annotations

import tempfile
from typing import Any

import numpy as np

from explore.strategies.base import StrategyError
from explore.strategies.goal_exploration import GoalExploration, check_latents, latent_space

ONLINE_BOOTSTRAP = 2000  # paper: 2000 random episodes before the online VAE (rig)
# CPU schedule (docs/goal_exploration.md): Adam lr 1e-3, batch 64; the paper used 200k
# iterations of batch 32 at lr 1e-5 on a GPU.
ONLINE_ITERATIONS = 1500


class OnlineLatentGoalExploration(GoalExploration):
    """Options (besides the goal-exploration ones): ``bootstrap`` (default 2000),
    ``vae_iterations`` (1500), ``vae_beta`` (1.0), ``vae_seed`` (0), ``latents`` ("raw" or
    "zscore" over the bootstrap's own outcome images)."""

    name = "rge-online"

    def __init__(self, **options: Any) -> None:
        options.setdefault("bootstrap", ONLINE_BOOTSTRAP)
        super().__init__(**options)
        check_latents(self.options.get("latents", "raw"), self.name)
        if self.bootstrap < 1:
            raise StrategyError(f"{self.name}: bootstrap must be at least 1 (the VAE's data)")
        self.vae = None

    def extra_options(self) -> tuple[str, ...]:
        return ("vae_iterations", "vae_beta", "vae_seed", "latents")

    def make_space(self) -> None:
        return None  # trained after the bootstrap

    def after_pending(self) -> None:
        if len(self._pending) < self.bootstrap:
            return
        from vision.vae import VaeConfig
        from vision.vae_train import TrainConfig, train_vae

        images = np.stack([r.image for r in self._pending])
        cfg = TrainConfig(
            iterations=int(self.options.get("vae_iterations", ONLINE_ITERATIONS)),
            seed=int(self.options.get("vae_seed", 0)),
        )
        with tempfile.TemporaryDirectory(prefix="ergo-online-vae-") as tmp:
            self.vae = train_vae(
                images, tmp, VaeConfig(beta=float(self.options.get("vae_beta", 1.0))), cfg,
                progress=False,
            )  # fmt: skip
        self._init_space(
            latent_space(self.vae, self.modular, self.options.get("latents", "raw"), self.name)
        )
        pending, self._pending = self._pending, []
        for rec in pending:
            self._learn(rec)

    def phase(self) -> str:
        return "bootstrap" if self.space is None else "rge-online"
