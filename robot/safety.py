"""Safety helpers shared by every backend: the thermal/load watchdog and signal handling.

- ``Watchdog`` trips when a joint's temperature or load stays over its limit for a hold time.
- ``torque_off_on_signals`` turns torque off on SIGINT/SIGTERM before the usual exception
  unwinds, so a Ctrl-C never leaves a stiff arm behind.
"""

from __future__ import annotations

import contextlib
import logging
import signal
import threading
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from robot.arm import Arm, JointState

log = logging.getLogger(__name__)

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
        checks = {
            "temperature": (
                np.nan_to_num(state.temperatures, nan=-np.inf),
                self.max_temperature_c,
                "C",
            ),
            "load": (np.abs(np.nan_to_num(state.loads, nan=0.0)), self.max_load, "of max torque"),
        }
        for kind, (values, limit, unit) in checks.items():
            over = np.flatnonzero(values > limit)
            if over.size == 0:
                self._since.pop(kind, None)
                continue
            start = self._since.setdefault(kind, state.timestamp)
            if state.timestamp - start >= self.hold_s:
                j = int(over[0])
                return (
                    f"safety stop: joint {j + 1} {kind} {values[j]:.2f} {unit} over the limit "
                    f"{limit} for {state.timestamp - start:.1f} s; torque off"
                )
        return None


@contextlib.contextmanager
def torque_off_on_signals(arm: Arm) -> Iterator[None]:
    """Within the block, SIGINT and SIGTERM turn the arm's torque off at once, then raise
    ``KeyboardInterrupt`` (SIGINT) or ``SystemExit(143)`` (SIGTERM) as usual.

    Only installs handlers in the main thread (Python's rule); elsewhere it is a no-op.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(signum: int, _frame: object) -> None:
        arm._emergency_torque_off()
        log.warning("signal %d: torque off", signum)
        if signum == signal.SIGINT:
            raise KeyboardInterrupt
        raise SystemExit(128 + signum)

    previous = {s: signal.signal(s, handler) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for s, h in previous.items():
            signal.signal(s, h)
