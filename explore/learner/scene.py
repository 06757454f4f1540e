"""What the learner may know of a rig's scene: the frame its engineered features and its metric
are defined in, and whether the scene changes between episodes.

A rig declares its scene (``explore.rigs.rig.rig_scene``, from the rig module's ``scene``);
strategies, engineered goal spaces and the metric take it, as they take the motor primitive's
``n_params``, so that a new rig needs no special case in the learner. The learner defines no
scene of its own: the rigs' scenes live with their rigs (the Ergo Jr's arena in
``explore/rigs/arena.py``, in metres, with a ring where the ball's centre lies and a ball that
stays where the last episode left it; ArmBalls' squares in ``explore/rigs/armballs.py``, in
units of the arm's reach, reset before every episode).
"""

from __future__ import annotations

from dataclasses import dataclass

# Engineered forms of an object's (x, y): "wrap-safe" (r_n, cos t, sin t) and "polar"
# (r_n, t / pi) are defined on a ring, "cartesian" (x / h, y / h) on every scene.
RING_FORMS = ("wrap-safe", "polar")
CARTESIAN = "cartesian"
FORMS = (*RING_FORMS, CARTESIAN)


@dataclass(frozen=True)
class Scene:
    """A rig's scene as the learner and the metric see it.

    Attributes:
        name: for messages.
        unit: the length unit of positions ("m", or "reach": the arm's reach is 1).
        ball_half_width: half the side of the square [-h, h]^2 that holds every ball position
            the rig can produce: the metric's grid (30 x 30 cells over it) and the scale of the
            cartesian features.
        hand_half_width: the hand's horizontal reach: the scale of the hand's features (the
            modular engineered space's hand module) and the end-effector grid.
        ring: (r_min, r_max), the radii between which the ball's centre lies (the polar forms'
            normalisation), or None where it may lie anywhere in the square.
        resets: every episode starts from the same scene (ArmBalls resets the ball, the
            distractor and the arm before each episode): the context carries no information,
            so goal spaces use none (context_dim 0).
        distractor: the scene holds a distractor, a second ball the arm cannot move (the
            engineered option ``distractor=null`` follows this).
    """

    name: str
    unit: str
    ball_half_width: float
    hand_half_width: float
    ring: tuple[float, float] | None = None
    resets: bool = False
    distractor: bool = False

    def __post_init__(self) -> None:
        if not (self.ball_half_width > 0 and self.hand_half_width > 0):
            raise ValueError(f"scene {self.name}: half widths must be positive")
        if self.ring is not None and not 0 <= self.ring[0] < self.ring[1]:
            raise ValueError(f"scene {self.name}: ring must be 0 <= r_min < r_max, got {self.ring}")

    @property
    def forms(self) -> tuple[str, ...]:
        """The engineered forms defined on this scene, the default first."""
        return FORMS if self.ring is not None else (CARTESIAN,)

    @property
    def default_form(self) -> str:
        return self.forms[0]
