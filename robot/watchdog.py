"""The thermal/load watchdog every arm runs on its readings (``robot.arm.Arm.read``): it trips
when a joint's temperature or load stays over its limit for a hold time, and the arm then cuts
torque and raises ``SafetyStop``."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from robot.joint_state import JointState

# XL-320 temperature limit: 65 C by default (control table address 12, ROBOTIS e-manual);
# we stop 5 C earlier. Load limit 0.9 of max torque held for 2 s: a guess that lets normal
# pushes of the ball through and catches a stalled joint.
DEFAULT_MAX_TEMPERATURE_C = 60.0
DEFAULT_MAX_LOAD = 0.9
DEFAULT_HOLD_S = 2.0

# Readings further apart than this do not make a continuous over-limit window (guess: 10
# control ticks at 40 Hz).
DEFAULT_MAX_GAP_S = 0.25


@dataclass
class Watchdog:
    """Trips when temperature or |load| of any joint stays over its limit for ``hold_s``,
    measured over readings no more than ``max_gap_s`` apart.

    NaN readings (unknown) never trip it.
    """

    max_temperature_c: float = DEFAULT_MAX_TEMPERATURE_C
    max_load: float = DEFAULT_MAX_LOAD
    hold_s: float = DEFAULT_HOLD_S
    max_gap_s: float = DEFAULT_MAX_GAP_S
    _since: dict[str, float] = field(default_factory=dict)
    _last: float | None = None

    def check(self, state: JointState) -> str | None:
        """Return a one-line reason to stop, or None."""
        if self._last is not None and state.timestamp - self._last > self.max_gap_s:
            self._since.clear()
        self._last = state.timestamp
        # Plain floats (six joints, every control tick: a third of numpy's cost); NaN
        # (unknown) compares False with any limit, so it never trips.
        checks = (
            ("temperature", np.asarray(state.temperatures).tolist(), self.max_temperature_c, "C"),
            ("load", [abs(v) for v in np.asarray(state.loads).tolist()], self.max_load,
             "of max torque"),
        )  # fmt: skip
        for kind, values, limit, unit in checks:
            over = [j for j, v in enumerate(values) if v > limit]
            if not over:
                self._since.pop(kind, None)
                continue
            start = self._since.setdefault(kind, state.timestamp)
            if state.timestamp - start >= self.hold_s:
                j = over[0]  # the first joint over its limit
                return (
                    f"safety stop: joint {j + 1} {kind} {values[j]:.2f} {unit} over the limit "
                    f"{limit} for {state.timestamp - start:.1f} s; torque off"
                )
        return None
