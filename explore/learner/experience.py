"""What the learner sees of the world: an ``Observation`` before a move (the context, at the
rest pose) and an ``Experience`` after it (a finished episode).

Strategies and goal spaces depend on these two shapes only, never on the rig or the run store:
``explore.runs.record.EpisodeRecord`` is an ``Experience``, and any rig that fills these fields
can be explored without a special case in the learner.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol

import numpy as np


@dataclass
class Observation:
    """What the rig sees at one moment.

    Attributes:
        ball: ball centre (x, y) in metres, shape (2,); NaN when not seen.
        image: square observation, shape (obs_size, obs_size, 3), BGR uint8; None if not rendered.
        frame: full overhead frame, shape (H, W, 3), BGR uint8; None if not rendered.
        distractor: the distractor's centre (x, y) in metres, shape (2,); NaN without one (the
            twin's ground truth; no tracker follows it yet).
    """

    ball: np.ndarray
    image: np.ndarray | None = None
    frame: np.ndarray | None = None
    distractor: np.ndarray = field(default_factory=lambda: np.full(2, np.nan))


class Experience(Protocol):
    """One finished episode, as the learner reads it.

    Attributes:
        episode: its index in the run.
        theta: the motor parameters played, shape (n_params,), in [-1, 1].
        goal: the goal aimed at, shape (g,) (empty when none), in the strategy's goal space.
        module: the goal-space module of the goal (-1 when none).
        kind: "random", "explore" or "exploit".
        context_ball, ball: ball (x, y) before and after the episode, m, shape (2,) (NaN: unseen).
        end_effector: tool tip at each tick, shape (T, 3), m (NaN where unknown).
        image: the outcome observation, shape (obs_size, obs_size, 3), BGR uint8.
    """

    episode: int
    theta: np.ndarray
    goal: np.ndarray
    module: int
    kind: str
    context_ball: np.ndarray
    ball: np.ndarray
    end_effector: np.ndarray
    image: np.ndarray
