"""The Ergo Jr rigs' motor primitive: the DMPs (``explore.learner.dmp``) over the joint ranges
chosen for the Ergo Jr's arena, the default ``Rig.motor`` of the twin and the physical rigs.

Units: radians.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

from explore.learner.dmp import Dmp, DmpConfig


def _deg(values: list[float]) -> tuple[float, ...]:
    return tuple(math.radians(v) for v in values)


# Joint ranges the normalised trajectory maps onto (radians), inside the Ergo Jr limits. Chosen
# for the twin's arena (docs/twin.md): m1 sweeps the servo's 300 degrees; m2 leans the arm
# forwards (to 110 degrees) or backwards (to -90, its limit), so the tool reaches the 60-degree
# sector behind the arm that m1 alone cannot face; m3/m5/m6 fold either way. Measured with
# experiments/touch_rate.py: random parameters move the ball in 7.3-8.0% of episodes (3 seeds x
# 1000),
# against 1.0-2.8% for the earlier forward-only ranges, whose dead sector behind the arm
# collected the ball for good.
ERGO_JR_LOWER = _deg([-150.0, -90.0, -90.0, -60.0, -90.0, -90.0])
ERGO_JR_UPPER = _deg([150.0, 110.0, 90.0, 60.0, 90.0, 90.0])


def ergo_jr_dmp(**config: Any) -> Dmp:
    """The Ergo Jr's DMPs over ``ERGO_JR_LOWER`` .. ``ERGO_JR_UPPER``; ``config``: other
    ``DmpConfig`` fields (``n_points``, ``rate_hz``, ``substeps``)."""
    base = DmpConfig(lower=ERGO_JR_LOWER, upper=ERGO_JR_UPPER)
    return Dmp(dataclasses.replace(base, **config))
