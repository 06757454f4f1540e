"""One Arm-2-Balls run whose bootstrap is the original campaign's for a published seed, the rest
ours (docs/results_armballs_stalls.md, "Runs confined by a folded arm").

The original's 100 bootstrap parameter vectors of seed ORIGINAL_SEED are rebuilt
(``armballs_folds.original_bootstrap``: numpy's legacy generator, as its ``mge_efr.py``) and
played in place of the strategy's own random draws of episodes 0-99 (the goal-exploration
strategies' ``_random`` is replaced for those episodes; a rebuilt vector is played as a
"random" episode, as the bootstrap's are); every later episode is the strategy's, drawn from
``--seed`` as usual. The rest of the arguments are ``ergo explore``'s:

    .venv/bin/python experiments/armballs_original_bootstrap.py 11 -- explore --rig arm2balls \\
        --strategy mge-efr --preset corl2018 --episodes 10000 --seed 536 \\
        --out runs/folds/orig11/mge-efr/seed-536 --no-progress
"""

from __future__ import annotations

import sys

import numpy as np
from armballs_folds import BOOTSTRAP, original_bootstrap  # experiments/, beside this script

from explore.learner.strategies import goal_exploration
from explore.learner.strategies.base import Proposal


def main(argv: list[str]) -> int:
    if len(argv) < 3 or argv[1] != "--":
        print(__doc__, file=sys.stderr)
        return 2
    rebuilt = original_bootstrap(int(argv[0]))  # (BOOTSTRAP, 49)
    own = goal_exploration.GoalExploration._random

    def bootstrap_then_own(
        self: goal_exploration.GoalExploration, rng: np.random.Generator
    ) -> Proposal:
        if self.n_seen < BOOTSTRAP:
            return Proposal(theta=rebuilt[self.n_seen].copy(), kind="random")
        return own(self, rng)

    goal_exploration.GoalExploration._random = bootstrap_then_own  # type: ignore[method-assign]
    from explore.cli import main as ergo

    return ergo(argv[2:])


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
