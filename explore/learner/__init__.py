"""The learner: motor primitives (DMP), goal spaces, the nearest-neighbour meta-policy,
learning-progress interests and the exploration strategies built on them. It sees episodes only
through ``experience`` (an ``Observation`` before a move, an ``Experience`` after it)."""
