"""The twin's physics nudged by one ulp, for finding tests that depend on its exact trajectory.

``ERGO_TEST_NUDGE_ULP=1 pytest ...``: every twin built (in the test process, and through
``tests/nudge_site/sitecustomize.py`` in every Python process the tests start) has its bodies'
masses one ulp heavier (``numpy.nextafter``), a stand-in for another CPU or MuJoCo build whose
floating point differs in the last bit, so that trajectories part after a few hundred steps
(the 150-episode rge-efr run of seed 5 ends with its ball elsewhere). A test that passes only
unnudged depends on the twin's exact trajectory, and fails on some other machine.
"""

from __future__ import annotations

import os

ENV = "ERGO_TEST_NUDGE_ULP"


def nudge_twin_physics() -> None:
    """Patch ``sim.twin.Twin`` so that every twin made after it has the nudged masses."""
    import numpy as np

    from sim.twin import Twin

    if getattr(Twin.__init__, "nudged", False):
        return
    init = Twin.__init__

    def nudged(self: Twin, *args, **kwargs) -> None:
        init(self, *args, **kwargs)
        mass = self.model.body_mass
        mass[1:] = np.nextafter(mass[1:], np.inf)
        self.reset()

    nudged.nudged = True  # type: ignore[attr-defined]
    Twin.__init__ = nudged


def nudge_if_asked() -> None:
    """Nudge this process's twins, and those of the processes it starts, if ``ENV`` is 1."""
    if os.environ.get(ENV) != "1":
        return
    site = os.path.join(os.path.dirname(os.path.abspath(__file__)), "nudge_site")
    path = os.environ.get("PYTHONPATH", "")
    if site not in path.split(os.pathsep):
        os.environ["PYTHONPATH"] = os.pathsep.join(p for p in (site, path) if p)
    nudge_twin_physics()
