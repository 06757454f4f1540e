"""Random Parameter Exploration (RPE): motor babbling, the paper's baseline."""

from __future__ import annotations

import numpy as np

from explore.learner.experience import Observation
from explore.learner.strategies.base import Proposal, Strategy


class RandomParameterExploration(Strategy):
    """Parameters drawn uniformly in [-1, 1]^n_params every episode."""

    name = "rpe"

    def propose(self, context: Observation, rng: np.random.Generator) -> Proposal:
        return Proposal(theta=rng.uniform(-1.0, 1.0, self.n_params), kind="random")
