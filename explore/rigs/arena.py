"""The Ergo Jr's round arena as the learner and the metric see it (an
``explore.learner.scene.Scene``): the twin's, and the physical rigs' as built. The twin's facts
live with the twin: the arena's dimensions are ``sim/models/make_scene.py``'s, the arm's reach
``robot/spec.py``'s; the learner receives them only through the rig's ``scene``.

In metres; the ball's centre lies on a ring between the arena's kerb and its wall, and the ball
stays where the last episode left it (the context changes between episodes).
"""

from __future__ import annotations

from explore.learner.scene import Scene
from robot.spec import ERGO_JR_REACH_M
from sim.models.make_scene import (
    ARENA_RADIUS,
    BALL_RADIUS,
    CAMERA_FOVY,
    CAMERA_HEIGHT,
    INNER_RADIUS,
    OUTER_RADIUS,
)
from vision.observation import OverheadView

#: The Ergo Jr's arena: the ball's centre between the kerb and the wall, less its radius
#: (0.13-0.17 m), inside the wall's square (+-0.20 m); the arm's horizontal reach.
TWIN_ARENA = Scene(
    name="the Ergo Jr arena",
    unit="m",
    ball_half_width=ARENA_RADIUS,
    hand_half_width=ERGO_JR_REACH_M,
    ring=(INNER_RADIUS + BALL_RADIUS, OUTER_RADIUS - BALL_RADIUS),
)
#: The ring where the ball's centre lies, (r_min, r_max) m: where the twin places balls (its
#: outcome dataset, the distractor's walk, the Gymnasium environment's resets).
R_MIN, R_MAX = TWIN_ARENA.ring  # type: ignore[misc]
#: The twin's overhead camera (sim/models/make_scene.py: straight above the arm's base at
#: CAMERA_HEIGHT, its image's axes along the arena's x and y, CAMERA_FOVY): the view a twin's
#: outcome image is (``sim.camera.SimCamera.read_square``), and the one a physical rig's
#: frames are mapped onto (``explore.rigs.ball``; tests/explore/rigs/test_arena_observation.py
#: checks the two agree).
TWIN_VIEW = OverheadView(CAMERA_HEIGHT, CAMERA_FOVY)
