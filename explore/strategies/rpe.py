"""Random Parameter Exploration (RPE): motor babbling, the paper's baseline."""

from __future__ import annotations

import numpy as np

from explore.dmp import N_PARAMS
from explore.episode import Observation
from explore.strategies.base import Proposal, Strategy


class RandomParameterExploration(Strategy):
    """Parameters drawn uniformly in [-1, 1]^48 every episode."""

    name = "rpe"

    def propose(self, context: Observation, rng: np.random.Generator) -> Proposal:
        return Proposal(theta=rng.uniform(-1.0, 1.0, N_PARAMS), kind="random")
